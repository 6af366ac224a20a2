#!/usr/bin/env python3
"""PEST's phi of a control file's model outputs, computed with pyemu (PEST++'s Python tools):
the control file read by pyemu.Pst, each output read with its instruction file by pyemu's
InstructionFile, phi = sum((weight * (obsval - simulated))**2) over the observations.

Usage: pest_phi.py CASE.pst DIR   (the instruction and output files in DIR)
Prints {"phi": ..., "observations": n}. Exits 3 when pyemu is missing.
"""
import json
import os
import sys
import warnings

try:
    import pyemu
    from pyemu.pst.pst_utils import InstructionFile
except ImportError as e:
    print(f"pyemu is missing: {e}", file=sys.stderr)
    sys.exit(3)

if len(sys.argv) != 3:
    sys.exit(__doc__)
pst_file, folder = sys.argv[1:]
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    pst = pyemu.Pst(pst_file)
    simulated = {}
    for ins, out in zip(pst.instruction_files, pst.output_files):
        frame = InstructionFile(os.path.join(folder, ins)).read_output_file(os.path.join(folder, out))
        simulated.update({name: float(v) for name, v in frame["obsval"].items()})
data = pst.observation_data
phi = 0.0
for name, value, weight in zip(data.obsnme, data.obsval, data.weight):
    phi += (float(weight) * (float(value) - simulated[name])) ** 2
print(json.dumps({"phi": phi, "observations": len(data)}))
