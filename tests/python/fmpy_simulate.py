#!/usr/bin/env python3
"""Simulate an FMU with FMPy onto an even grid and write the outputs as CSV: the second
opinion calib's FMU runs are checked against (tests/fmu_crosscheck.rs, fmu_inputs.rs).

Usage: fmpy_simulate.py FMU {me|cs} STOP STEP RTOL OUT.csv [NAME ...]
                        [--input FILE.csv [--hold]] [--set NAME=VALUE ...]

Model Exchange runs FMPy's CVode at relative tolerance RTOL; Co-Simulation steps the FMU
from one output time to the next (communication step STEP) with RTOL as the FMU's
tolerance. Outputs are recorded at the grid times 0, STEP, ... STOP only (after the events
at those times). Without NAMEs, every variable FMPy records by default (the outputs) is
written.

--input drives the FMU's inputs from a CSV file (time, then one column per input, named
after it), as `calib simulate --input` reads it: FMPy interpolates Real inputs linearly and
holds Integer, Boolean and discrete ones (rounded; true when non-zero). With --hold every
input is held from one sample to the next (given to FMPy as steps: each sample repeated at
the next sample's time). Without --input, inputs keep their start values. --set gives a
parameter a start value.
"""
import argparse
import csv

import fmpy
import numpy as np


def input_signals(path, hold, description):
    """The input file as FMPy's structured array, each column of its variable's type."""
    with open(path, newline="") as f:
        rows = [r for r in csv.reader(f) if r]
    header = [h.strip() for h in rows[0]]
    data = np.array([[float(v) for v in r] for r in rows[1:]])
    if hold:
        # (t0, v0), (t1, v0), (t1, v1), (t2, v1), ...: a step at every sample.
        stepped = [data[0]]
        for k in range(1, len(data)):
            stepped.append(np.concatenate(([data[k][0]], data[k - 1][1:])))
            stepped.append(data[k])
        data = np.array(stepped)
    types = {v.name: v.type for v in description.modelVariables}
    dtype = [("time", np.double)]
    columns = [data[:, 0]]
    for k, name in enumerate(header[1:], start=1):
        kind = types.get(name)
        if kind in ("Integer", "Int32", "Enumeration"):
            dtype.append((name, np.int32))
            columns.append(np.round(data[:, k]).astype(np.int32))
        elif kind == "Boolean":
            dtype.append((name, np.bool_))
            columns.append(np.round(data[:, k]) != 0)
        else:
            dtype.append((name, np.double))
            columns.append(data[:, k])
    signals = np.zeros(len(data), dtype=dtype)
    for (name, _), column in zip(dtype, columns):
        signals[name] = column
    return signals


def main():
    parser = argparse.ArgumentParser(usage=__doc__)
    parser.add_argument("fmu")
    parser.add_argument("interface", choices=["me", "cs"])
    parser.add_argument("stop", type=float)
    parser.add_argument("step", type=float)
    parser.add_argument("rtol", type=float)
    parser.add_argument("out")
    parser.add_argument("names", nargs="*")
    parser.add_argument("--input")
    parser.add_argument("--hold", action="store_true")
    parser.add_argument("--set", action="append", default=[])
    args = parser.parse_args()
    kind = {"me": "ModelExchange", "cs": "CoSimulation"}[args.interface]
    signals = None
    if args.input:
        description = fmpy.read_model_description(args.fmu)
        signals = input_signals(args.input, args.hold, description)
    start_values = {}
    for assignment in args.set:
        name, value = assignment.split("=", 1)
        start_values[name.strip()] = float(value)
    result = fmpy.simulate_fmu(
        args.fmu,
        fmi_type=kind,
        start_time=0.0,
        stop_time=args.stop,
        output_interval=args.step,
        relative_tolerance=args.rtol,
        record_events=False,
        output=args.names or None,
        input=signals,
        start_values=start_values,
        validate=False,
    )
    columns = result.dtype.names
    with open(args.out, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(columns)
        for row in result:
            w.writerow([repr(float(row[c])) for c in columns])


if __name__ == "__main__":
    main()
