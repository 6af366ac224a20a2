#!/usr/bin/env python3
"""Gather FMUs exported by real modelling tools, with the data their projects ship beside them.

The FMUs come from Python packages on PyPI that keep them for their own tests and examples;
nothing is copied into the repository. Usage: real_tool_fmus.py DEST

DEST/
  gemseo-fmu/<Model>.fmu        OpenModelica 1.19-1.21 (FMI 2.0, ME + CS), PythonFMU3 (FMI 3.0 CS)
  modestpy/simple2R1C/          JModelica.org 2R1C room (FMI 2.0 CS, inputs): FMU, inputs.csv,
                                result.csv, parameters.csv
  aixcalibuha/                  Dymola PumpAndValve (FMI 2.0 CS) and HeatPumpSystemWithInput,
                                with the example's measured records (HDF5)
  SOURCES                       package, version and licence of each
Each package is downloaded once; DEST/.complete marks a finished gathering.
"""
import io
import os
import subprocess
import sys
import tarfile
import tempfile
import zipfile

PACKAGES = [
    # (pip requirement, extra pip arguments, licence)
    ("gemseo-fmu==3.1.1", [], "LGPL-3.0"),
    ("modestpy==0.1.1", [], "BSD-2-Clause"),
    ("aixcalibuha==0.2.2", ["--no-binary", "aixcalibuha"], "MIT"),
]


def download(requirement, extra, into):
    subprocess.run(
        [sys.executable, "-m", "pip", "download", "--quiet", "--disable-pip-version-check",
         "--no-deps", "--dest", into, *extra, requirement],
        check=True,
    )
    name = requirement.split("==")[0].replace("-", "_")
    for f in os.listdir(into):
        if f.replace("-", "_").lower().startswith(name.lower()):
            return os.path.join(into, f)
    raise SystemExit(f"pip downloaded nothing for {requirement}")


def members(archive):
    """(name, bytes) of every file in a wheel (zip) or an sdist (tar.gz)."""
    if archive.endswith(".whl") or archive.endswith(".zip"):
        with zipfile.ZipFile(archive) as z:
            for n in z.namelist():
                if not n.endswith("/"):
                    yield n, lambda n=n, z=z: z.read(n)
    else:
        with tarfile.open(archive) as t:
            for m in t.getmembers():
                if m.isfile():
                    yield m.name, lambda m=m, t=t: t.extractfile(m).read()


def put(dest, relative, data):
    path = os.path.join(dest, relative)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "wb") as f:
        f.write(data)


def main():
    if len(sys.argv) != 2:
        raise SystemExit(__doc__)
    dest = sys.argv[1]
    if os.path.exists(os.path.join(dest, ".complete")):
        return
    os.makedirs(dest, exist_ok=True)
    sources = []
    with tempfile.TemporaryDirectory() as tmp:
        for requirement, extra, licence in PACKAGES:
            archive = download(requirement, extra, tmp)
            sources.append(f"{requirement}\t{os.path.basename(archive)}\t{licence}")
            for name, read in members(archive):
                if "/fmu_files/linux/" in name and name.endswith(".fmu"):
                    put(dest, "gemseo-fmu/" + os.path.basename(name), read())
                elif "/resources/simple2R1C/" in name and not name.endswith(("_win32.fmu", "_win64.fmu")):
                    put(dest, "modestpy/simple2R1C/" + os.path.basename(name), read())
                elif "/examples/model/" in name and name.endswith(".fmu") and "_windows" not in name:
                    put(dest, "aixcalibuha/" + os.path.basename(name), read())
                elif "/examples/data/" in name and name.endswith(".hdf"):
                    put(dest, "aixcalibuha/data/" + os.path.basename(name), read())
    with open(os.path.join(dest, "SOURCES"), "w") as f:
        f.write("\n".join(sources) + "\n")
    open(os.path.join(dest, ".complete"), "w").close()


if __name__ == "__main__":
    main()
