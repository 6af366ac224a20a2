#!/usr/bin/env python3
"""The objective of the Furuta rig's free swing against a recorded swing, by the independent
simulator of ``furuta_driven.py`` (scipy; no code shared with calib's worker).

Usage: furuta_objective.py RECORD STOP ARM_FRICTION,PENDULUM_FRICTION [...]

RECORD is a MAT file with variables ``time``, ``phi`` and ``theta`` (the seed's real rig,
``FurutaData.mat``) or a CSV with columns ``time_s``, ``arm_angle_rad``,
``pendulum_angle_rad``. For each pair of Coulomb frictions the rig (geometry and start of
``furuta_driven.py``, no motor torque) is simulated to the record's sample times up to STOP
seconds, and ``sum_t (phi_sim - phi)^2 + (theta_sim - theta)^2`` over those samples is
printed as JSON: ``{"objectives": [...], "samples": N}``, one objective per pair, in order.
"""
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from furuta_driven import RIG, START, Rig, simulate  # noqa: E402


def record(path):
    if path.endswith(".mat"):
        from scipy.io import loadmat

        data = loadmat(path)
        flat = {k: np.asarray(v, dtype=float).ravel() for k, v in data.items() if not k.startswith("__")}
        return flat["time"], flat["phi"], flat["theta"]
    table = np.genfromtxt(path, delimiter=",", names=True)
    return table["time_s"], table["arm_angle_rad"], table["pendulum_angle_rad"]


def main():
    path, stop = sys.argv[1], float(sys.argv[2])
    times, phi, theta = record(path)
    keep = times <= stop + 1e-9 * max(1.0, stop)
    times, phi, theta = times[keep], phi[keep], theta[keep]
    y0 = (START["phi0"], START["theta0"], START["dphi0"], START["dtheta0"])
    objectives = []
    for pair in sys.argv[3:]:
        arm, pendulum = (float(v) for v in pair.split(","))
        rig = Rig(RIG, (arm, pendulum), (0.0, 0.0))
        states, _ = simulate(rig, y0, times, np.zeros(len(times)))
        objectives.append(float(np.sum((states[:, 0] - phi) ** 2) + np.sum((states[:, 1] - theta) ** 2)))
    print(json.dumps({"objectives": objectives, "samples": int(len(times))}))


if __name__ == "__main__":
    main()
