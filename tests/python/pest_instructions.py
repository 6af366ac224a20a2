#!/usr/bin/env python3
"""Read model outputs with PEST instruction files through pyemu (PEST++'s Python tools), an
implementation calib shares no code with.

Usage: pest_instructions.py INS OUT [INS OUT ...]
Prints one JSON object per pair on standard output: {observation: value}, the dummies left
out. Exits 3 when pyemu is missing.
"""
import json
import sys
import warnings

try:
    from pyemu.pst.pst_utils import InstructionFile
except ImportError as e:
    print(f"pyemu is missing: {e}", file=sys.stderr)
    sys.exit(3)

args = sys.argv[1:]
if not args or len(args) % 2:
    sys.exit(__doc__)
for ins, out in zip(args[::2], args[1::2]):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        frame = InstructionFile(ins).read_output_file(out)
    print(json.dumps({name: float(v) for name, v in frame["obsval"].items()}))
