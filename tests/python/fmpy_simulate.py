#!/usr/bin/env python3
"""Simulate an FMU with FMPy onto an even grid and write the outputs as CSV: the second
opinion calib's FMU runs are checked against (tests/fmu_crosscheck.rs).

Usage: fmpy_simulate.py FMU {me|cs} STOP STEP RTOL OUT.csv [NAME ...]

Model Exchange runs FMPy's CVode at relative tolerance RTOL; Co-Simulation steps the FMU
from one output time to the next (communication step STEP) with RTOL as the FMU's
tolerance. Outputs are recorded at the grid times 0, STEP, ... STOP only (after the events
at those times); inputs keep their start values. Without NAMEs, every variable FMPy records
by default (the outputs) is written.
"""
import csv
import sys

import fmpy


def main():
    if len(sys.argv) < 7:
        raise SystemExit(__doc__)
    path, interface, stop, step, rtol, out = sys.argv[1:7]
    names = sys.argv[7:] or None
    kind = {"me": "ModelExchange", "cs": "CoSimulation"}[interface]
    result = fmpy.simulate_fmu(
        path,
        fmi_type=kind,
        start_time=0.0,
        stop_time=float(stop),
        output_interval=float(step),
        relative_tolerance=float(rtol),
        record_events=False,
        output=names,
        validate=False,
    )
    columns = result.dtype.names
    with open(out, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(columns)
        for row in result:
            w.writerow([repr(float(row[c])) for c in columns])


if __name__ == "__main__":
    main()
