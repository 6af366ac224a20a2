#!/usr/bin/env python3
"""A record of the driven Furuta rig with a torque on the arm that calib's effects do not hold.

A wrapper of ``furuta_driven.py`` (same rig, same motor torque, same noise and 4096-count
quantisation, same CSV and truth): it adds to the arm joint's generalised torque one or more
terms outside the worker's library of effects, then runs that script's ``main`` with every
other argument. The terms, positive in the direction of the arm angle ``phi``:

``--cogging A`` (with ``--cogging-k K``, default 8, ``--cogging-phase C``, default 0)
    cogging of the motor, ``A sin(K phi + C)`` [N m];
``--arm-cubic K3``
    a hardening spring on the arm, ``-K3 phi^3`` [N m / rad^3];
``--arm-cubic-drag D3``
    a drag cubic in the arm speed, ``-D3 phi'^3`` [N m s^3 / rad^3].

The truth printed on stdout (and written with ``--truth``) is that of ``furuta_driven.py``
with an ``extra_arm_torque`` entry naming the terms and their values. The records it writes
serve the discovery tests (tests/it/discovery.rs).
"""

import argparse
import contextlib
import io
import json
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import furuta_driven  # noqa: E402  (the sibling script)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0], add_help=False)
    p.add_argument("--cogging", type=float, default=0.0, help="cogging amplitude A [N m]")
    p.add_argument("--cogging-k", type=float, default=8.0, help="cogging periods per revolution K")
    p.add_argument("--cogging-phase", type=float, default=0.0, help="cogging phase C [rad]")
    p.add_argument("--arm-cubic", type=float, default=0.0, help="cubic spring K3 [N m/rad^3]: -K3 phi^3")
    p.add_argument("--arm-cubic-drag", type=float, default=0.0, help="cubic drag D3 [N m s^3/rad^3]: -D3 dphi^3")
    p.add_argument("-h", "--help", action="store_true")
    args, rest = p.parse_known_args(argv)
    if args.help:
        p.print_help()
        print("\nEvery other argument goes to furuta_driven.py:\n")
        furuta_driven.main(["--help"])
        return

    def extra(y):
        phi = y[0]
        return (
            args.cogging * math.sin(args.cogging_k * phi + args.cogging_phase)
            - args.arm_cubic * phi**3
            - args.arm_cubic_drag * y[2] ** 3
        )

    base = furuta_driven.Rig.forces

    def forces(self, y, u):
        r1, r2, a, cc = base(self, y, u)
        return r1 + extra(y), r2, a, cc

    furuta_driven.Rig.forces = forces
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        furuta_driven.main(rest)
    truth = json.loads(printed.getvalue())
    truth["extra_arm_torque"] = {
        "cogging": {"amplitude_Nm": args.cogging, "k": args.cogging_k, "phase_rad": args.cogging_phase},
        "cubic_spring_Nm_per_rad3": args.arm_cubic,
        "cubic_drag_Nms3_per_rad3": args.arm_cubic_drag,
    }
    text = json.dumps(truth, indent=1)
    if "--truth" in rest:
        with open(rest[rest.index("--truth") + 1], "w") as f:
            f.write(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
