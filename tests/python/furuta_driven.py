#!/usr/bin/env python3
"""A record of the Furuta pendulum rig driven by a measured arm motor torque.

An independent simulator of the rig of the worker's ``furuta`` model (same equations, see
model/src/models/furuta.rs), written with scipy and numpy only and sharing no code with the
worker, so that the worker's model and its inputs can be checked against it. It writes a CSV
with columns ``time_s, arm_angle_rad, pendulum_angle_rad, motor_torque_Nm`` and prints the
truth it used as JSON on stdout (and, with ``--truth FILE``, into that file).

Equations
---------
State ``[phi, theta, dphi, dtheta]``: arm angle about the vertical axis, pendulum angle about
the arm axis, ``theta = 0`` upright. With ``s = sin(theta)``, ``c = cos(theta)``::

    A(theta) = J + m L1^2 + m l^2 s^2 + Iyy c^2 + Izz s^2,   A' = 2 (m l^2 + Izz - Iyy) s c
    B = Ixx + m l^2,   C = m L1 l
    [ A    -C c ] [phi'']     [ tau1 - A' theta' phi' - C s theta'^2 ]
    [ -C c  B   ] [theta''] = [ tau2 + A'/2 phi'^2 + m g l s          ]

``tau1 = u(t) + b1 - d1 phi' - c1 phi' |phi'| - k1 phi + f1`` and
``tau2 = b2 - d2 theta' - c2 theta' |theta'| - k2 theta + f2``: ``b1``, ``b2`` optional
constant torques (``--<joint>-bias``), ``u`` is the motor torque on the
arm joint (positive in the direction of ``phi``), ``d1``, ``d2`` optional viscous frictions,
``c1``, ``c2`` optional quadratic drags, ``k1``, ``k2`` optional torsional springs (the torque
``-k q`` about the joint's zero angle, acting on a stuck joint too, which its friction must
hold) and ``f1``, ``f2`` the Coulomb bearing frictions.

Sensor effects
--------------
Each recorded angle may carry a dead time ``--<joint>-delay d`` (the angle at ``t - d``, the
start value before ``d``), then a first-order sensor of time constant ``--<joint>-lag T``
(``T y' + y = x``, settled at the start, ``x`` linear between the record's samples), then a
relative gain error and an offset (``(1 + g) y + o``, ``--<joint>-gain``,
``--<joint>-offset``), before the noise and the quantisation below. These are the
definitions of the worker's ``delay(...)``, ``lag(...)``, ``gain(...)`` and ``offset(...)``
effects (model/src/effects.rs); the spring, drag, friction and constant torque terms are
those of its ``stiffness.<joint>``, ``quadratic_drag.<joint>``,
``viscous_friction.<joint>`` and ``torque_bias.<joint>`` (model/src/models/furuta.rs; its
bias is the opposite torque, ``-t0``).

Stick-slip
----------
Each joint is in one of three modes: sliding forward (``f = -F``), sliding backward
(``f = +F``) or stuck (zero speed, zero acceleration, ``f`` whatever holds it: the 2x2 system
solved with that joint's acceleration fixed at 0). ``solve_ivp`` locates terminal events and
the integration restarts in the new mode: a sliding joint whose speed crosses zero is set to
rest and sticks if the holding torque is within ``F`` (else it slides on the way it is driven);
a stuck joint breaks away when its holding torque reaches ``F``. Modes at rest are chosen as
the consistent combination with the most joints stuck (with a positive definite mass matrix
the combination is unique).

Motor torque
------------
``u`` is sampled at the record's rate (100 Hz) and is linear between samples, the convention a
calibration uses when it interpolates the recorded column; the integration restarts at every
sample so the kinks of ``u`` never fall inside a step. The profile (``--amplitude`` a, default
0.03 N m, three times the arm's Coulomb friction) repeats every 20 s: rest, a doublet of
steps +-a (0.6 s each), two pulses -+1.5 a (0.3 s each), a chirp 0.2 -> 1.5 Hz of amplitude a,
a pause, and a sum of two sines (0.45 and 1.3 Hz). Over the default 20 s the arm turns by up
to 9 rad, is stuck 8 times for about 1.8 s in all, and the pendulum swings widely about
its hanging position (time stuck and arm range are part of the printed truth). The recorded torque column is the applied torque itself, noise
free by default: a motor's current measurement is far cleaner than the angles, and a clean
column keeps the model input exact so that the calibration test measures the model, not an
errors-in-variables bias. ``--torque-noise`` adds gaussian noise to the recorded column only.

Angles are recorded as the rig's encoders see them: gaussian noise (``--noise``, 0.002 rad)
added, then quantised to 4096 counts per revolution, seeded (``--seed``); ``--clean`` writes
the exact trajectory instead.

Validation
----------
With ``--no-torque --stop 40`` and the truth of ``furuta_rig.json`` (the defaults), the clean
trajectory matches the independent record ``furuta_clean.csv`` with an RMS difference over
0-40 s of 0.00203 rad on the arm angle and 0.00202 rad on the pendulum angle (largest
differences 0.0078 and 0.0082 rad): the noise level of that record, whose 0.002 rad noise and
4096-count quantisation give sqrt(0.002^2 + (2 pi/4096)^2/12) = 0.00205 rad. With
``--arm-viscous 0.002`` it matches ``furuta_viscous_arm.csv`` to 0.00208 and 0.00202 rad.
Reproduce with ``--no-torque --stop 40 --clean --compare FILE`` (the figures are printed under
``compare``). With the pendulum held hanging by its friction, the arm follows the closed forms
to 1e-14 rad: no creep under a torque below its friction, 0.5 (u - F)/A t^2 above it, and a
torque ramp breaks it away when it reaches F. The default driven record (20 s) is not
chaotic: a relative change of 1e-6 in the arm friction moves the arm by 5e-6 rad RMS, 1e-2 by
0.05 rad.
"""

import argparse
import json
import math
import sys

import numpy as np
from scipy.integrate import solve_ivp

FORWARD, BACKWARD, STUCK = "forward", "backward", "stuck"

# The rig (furuta_rig.json): geometry, start state and true frictions.
RIG = {
    "g": 9.81,
    "arm_length": 0.245,
    "arm_inertia": 0.001,
    "pend_mass": 0.035,
    "pend_com": 0.2105,
    "pend_Ixx": 0.00384,
    "pend_Iyy": 0.001,
    "pend_Izz": 0.001,
}
START = {"phi0": 0.0, "theta0": math.pi / 6.0, "dphi0": 0.0, "dtheta0": 0.0}
TRUE_FRICTION = {"armFriction": 0.010125, "pendulumFriction": 0.00117}
RATE_HZ = 100
COUNTS_PER_REV = 4096
NOISE_RAD = 0.002
PERIOD_S = 20.0


def torque_profile(t, amplitude):
    """The motor torque [N m] at times ``t`` (one 20 s pattern, repeated)."""
    a = amplitude
    tau = np.mod(np.asarray(t, dtype=float), PERIOD_S)
    u = np.zeros_like(tau)
    u = np.where((tau >= 1.0) & (tau < 1.6), a, u)  # a doublet of steps
    u = np.where((tau >= 1.6) & (tau < 2.2), -a, u)
    u = np.where((tau >= 3.5) & (tau < 3.8), -1.5 * a, u)  # two short pulses
    u = np.where((tau >= 3.8) & (tau < 4.1), 1.5 * a, u)
    chirp = (tau >= 5.0) & (tau < 12.0)
    tc = tau - 5.0
    f0, f1, span = 0.2, 1.5, 7.0
    u = np.where(chirp, a * np.sin(2.0 * math.pi * (f0 * tc + 0.5 * (f1 - f0) * tc**2 / span)), u)
    sines = tau >= 14.0
    ts = tau - 14.0
    u = np.where(
        sines,
        a * (0.7 * np.sin(2.0 * math.pi * 0.45 * ts) + 0.5 * np.sin(2.0 * math.pi * 1.3 * ts + 1.0)),
        u,
    )
    return u


class Rig:
    def __init__(self, geometry, friction, viscous, drag=(0.0, 0.0), stiffness=(0.0, 0.0), bias=(0.0, 0.0)):
        g = geometry
        m, l1, l = g["pend_mass"], g["arm_length"], g["pend_com"]
        self.a0 = g["arm_inertia"] + m * l1 * l1 + g["pend_Iyy"]
        self.a1 = m * l * l + g["pend_Izz"] - g["pend_Iyy"]
        self.b = g["pend_Ixx"] + m * l * l
        self.c = m * l1 * l
        self.mgl = m * g["g"] * l
        self.friction = list(friction)
        self.viscous = list(viscous)
        self.drag = list(drag)
        self.stiffness = list(stiffness)
        self.bias = list(bias)

    def forces(self, y, u):
        """Generalised forces without Coulomb friction, and the mass matrix (A, C c)."""
        s, c = math.sin(y[1]), math.cos(y[1])
        w1, w2 = y[2], y[3]
        a = self.a0 + self.a1 * s * s
        da = 2.0 * self.a1 * s * c
        r1 = u - da * w2 * w1 - self.c * s * w2 * w2 - self.viscous[0] * w1
        r2 = 0.5 * da * w1 * w1 + self.mgl * s - self.viscous[1] * w2
        r1 += self.bias[0] - self.drag[0] * w1 * abs(w1) - self.stiffness[0] * y[0]
        r2 += self.bias[1] - self.drag[1] * w2 * abs(w2) - self.stiffness[1] * y[1]
        return r1, r2, a, self.c * c

    def dynamics(self, y, u, modes):
        """Accelerations and Coulomb friction torques with the joints in ``modes``."""
        r1, r2, a, cc = self.forces(y, u)

        def sliding(j):
            return {FORWARD: -self.friction[j], BACKWARD: self.friction[j]}[modes[j]]

        if modes[0] == STUCK and modes[1] == STUCK:
            return (0.0, 0.0), (-r1, -r2)
        if modes[0] == STUCK:
            f2 = sliding(1)
            acc2 = (r2 + f2) / self.b
            return (0.0, acc2), (-cc * acc2 - r1, f2)
        if modes[1] == STUCK:
            f1 = sliding(0)
            acc1 = (r1 + f1) / a
            return (acc1, 0.0), (f1, -cc * acc1 - r2)
        f1, f2 = sliding(0), sliding(1)
        det = a * self.b - cc * cc
        q1, q2 = r1 + f1, r2 + f2
        return ((self.b * q1 + cc * q2) / det, (cc * q1 + a * q2) / det), (f1, f2)

    def settle(self, y, u, must_slide=()):
        """Modes consistent with state ``y``: moving joints slide their way; joints at rest
        stick when their friction holds them and slide the way they are driven otherwise."""
        options = []
        for j in range(2):
            w = y[2 + j]
            if w > 0.0:
                options.append([FORWARD])
            elif w < 0.0:
                options.append([BACKWARD])
            elif j in must_slide or self.friction[j] == 0.0:
                options.append([FORWARD, BACKWARD])
            else:
                options.append([STUCK, FORWARD, BACKWARD])
        best = None
        for m0 in options[0]:
            for m1 in options[1]:
                modes = (m0, m1)
                acc, fr = self.dynamics(y, u, modes)
                violation = 0.0
                for j in range(2):
                    if y[2 + j] != 0.0:
                        continue
                    if modes[j] == STUCK:
                        violation += max(0.0, abs(fr[j]) - self.friction[j])
                    elif modes[j] == FORWARD:
                        violation += max(0.0, -acc[j])
                    else:
                        violation += max(0.0, acc[j])
                key = (violation > 1e-12 * (1.0 + sum(self.friction)), violation, -modes.count(STUCK))
                if best is None or key < best[0]:
                    best = (key, modes)
        return best[1]


def first_order(times, x, tau):
    """A first-order sensor ``tau y' + y = x`` of the sampled signal ``x`` (linear between
    its samples), settled at the start (``y[0] = x[0]``), solved exactly step by step."""
    if tau <= 0.0:
        return np.asarray(x, dtype=float)
    y = np.empty(len(x))
    y[0] = x[0]
    for k in range(1, len(x)):
        h = times[k] - times[k - 1]
        e = math.exp(-h / tau)
        slope = (x[k] - x[k - 1]) / h
        # The response to x(t) = x[k-1] + slope (t - t[k-1]) from y[k-1] over h.
        y[k] = x[k] - slope * tau + (y[k - 1] - x[k - 1] + slope * tau) * e
    return y


def simulate(rig, y0, times, torque):
    """States at ``times`` (increasing), the motor torque linear between its samples."""
    y = np.array(y0, dtype=float)
    out = np.empty((len(times), 4))
    out[0] = y
    modes = rig.settle(y, torque[0])
    stats = {"events": 0, "arm_stuck_s": 0.0, "pendulum_stuck_s": 0.0, "arm_sticks": 0, "pendulum_sticks": 0}
    for k in range(len(times) - 1):
        t0, t1 = times[k], times[k + 1]
        u0, u1 = torque[k], torque[k + 1]

        def u_at(t):
            return u0 + (u1 - u0) * (t - t0) / (t1 - t0)

        t = t0
        while t < t1:
            # Joints at rest, and their speed held at exactly 0.
            m = modes

            def rhs(tt, yy):
                acc, _ = rig.dynamics(yy, u_at(tt), m)
                return [yy[2], yy[3], acc[0], acc[1]]

            events = []
            for j in range(2):
                if m[j] == STUCK:
                    def ev(tt, yy, j=j):
                        _, fr = rig.dynamics(yy, u_at(tt), m)
                        return rig.friction[j] - abs(fr[j])

                    ev.direction = -1.0
                elif rig.friction[j] == 0.0:
                    def ev(tt, yy):
                        return 1.0

                    ev.direction = 0.0
                else:
                    sign = 1.0 if m[j] == FORWARD else -1.0

                    def ev(tt, yy, j=j, sign=sign):
                        return sign * yy[2 + j]

                    ev.direction = -1.0
                ev.terminal = True
                events.append(ev)
            sol = solve_ivp(rhs, (t, t1), y, method="DOP853", rtol=1e-10, atol=1e-12, events=events)
            if sol.status < 0:
                raise RuntimeError(sol.message)
            for j in range(2):
                if m[j] == STUCK:
                    stats[("arm", "pendulum")[j] + "_stuck_s"] += sol.t[-1] - t
            if sol.status == 1:
                # An event: restart there in the modes the state now calls for.
                te = sol.t[-1]
                y = sol.y[:, -1].copy()
                hit = [j for j in range(2) if len(sol.t_events[j]) and sol.t_events[j][-1] == te]
                must_slide = []
                for j in hit:
                    if m[j] == STUCK:
                        must_slide.append(j)
                    else:
                        y[2 + j] = 0.0
                for j in range(2):
                    if m[j] == STUCK:
                        y[2 + j] = 0.0
                t = te
                modes = rig.settle(y, u_at(t), must_slide)
                for j in range(2):
                    if modes[j] == STUCK and m[j] != STUCK:
                        stats[("arm", "pendulum")[j] + "_sticks"] += 1
                stats["events"] += 1
            else:
                y = sol.y[:, -1].copy()
                t = t1
        out[k + 1] = y
    return out, stats


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", default="furuta_driven.csv", help="CSV to write")
    p.add_argument("--stop", type=float, default=20.0, help="record length [s]")
    p.add_argument("--theta0", type=float, default=START["theta0"], help="initial pendulum angle [rad], 0 upright")
    p.add_argument("--arm-friction", type=float, default=TRUE_FRICTION["armFriction"], help="arm Coulomb friction [N m]")
    p.add_argument(
        "--pendulum-friction", type=float, default=TRUE_FRICTION["pendulumFriction"], help="pendulum Coulomb friction [N m]"
    )
    p.add_argument("--arm-viscous", type=float, default=0.0, help="arm viscous friction [N m s/rad]")
    p.add_argument("--pendulum-viscous", type=float, default=0.0, help="pendulum viscous friction [N m s/rad]")
    for joint in ("arm", "pendulum"):
        p.add_argument(f"--{joint}-drag", type=float, default=0.0, help=f"{joint} quadratic drag [N m s2/rad2]")
        p.add_argument(f"--{joint}-stiffness", type=float, default=0.0, help=f"{joint} torsional spring [N m/rad]")
        p.add_argument(f"--{joint}-bias", type=float, default=0.0, help=f"constant torque on the {joint} joint [N m]")
        p.add_argument(f"--{joint}-lag", type=float, default=0.0, help=f"time constant of a first-order {joint} sensor [s]")
        p.add_argument(f"--{joint}-offset", type=float, default=0.0, help=f"offset of the recorded {joint} angle [rad]")
        p.add_argument(f"--{joint}-gain", type=float, default=0.0, help=f"relative gain error of the recorded {joint} angle")
        p.add_argument(f"--{joint}-delay", type=float, default=0.0, help=f"dead time of the recorded {joint} angle [s]")
    p.add_argument("--no-torque", action="store_true", help="free swing: no motor torque")
    p.add_argument("--amplitude", type=float, default=0.03, help="motor torque amplitude [N m]")
    p.add_argument("--seed", type=int, default=1, help="seed of the measurement noise")
    p.add_argument("--noise", type=float, default=NOISE_RAD, help="angle noise std [rad]")
    p.add_argument("--torque-noise", type=float, default=0.0, help="noise std of the recorded torque column [N m]")
    p.add_argument("--clean", action="store_true", help="write the exact angles (no noise, no quantisation)")
    p.add_argument("--truth", help="also write the truth JSON to this file")
    p.add_argument("--compare", help="print RMS differences of the clean angles to this record (CSV)")
    args = p.parse_args(argv)

    n = int(round(args.stop * RATE_HZ))
    times = np.arange(n + 1) / RATE_HZ
    torque = np.zeros(n + 1) if args.no_torque else torque_profile(times, args.amplitude)
    rig = Rig(
        RIG,
        (args.arm_friction, args.pendulum_friction),
        (args.arm_viscous, args.pendulum_viscous),
        (args.arm_drag, args.pendulum_drag),
        (args.arm_stiffness, args.pendulum_stiffness),
        (args.arm_bias, args.pendulum_bias),
    )
    y0 = (START["phi0"], args.theta0, START["dphi0"], START["dtheta0"])
    delays = (args.arm_delay, args.pendulum_delay)
    if any(d < 0.0 for d in delays):
        sys.exit("--arm-delay, --pendulum-delay: a dead time is not negative")
    # The delayed sampling times too; the torque stays linear between its 100 Hz samples.
    # (rounded to 1e-9 s, so that a delay of whole samples adds no times a hair apart)
    grid = np.unique(np.round(np.concatenate([times] + [np.maximum(times - d, 0.0) for d in delays]), 9))
    states_on_grid, stats = simulate(rig, y0, grid, np.interp(grid, times, torque))
    states = np.empty((len(times), 4))
    states[:] = states_on_grid[np.searchsorted(grid, np.round(times, 9))]
    recorded = np.empty((len(times), 2))
    for j, (d, g, o) in enumerate(
        [(args.arm_delay, args.arm_gain, args.arm_offset), (args.pendulum_delay, args.pendulum_gain, args.pendulum_offset)]
    ):
        at = np.searchsorted(grid, np.round(np.maximum(times - d, 0.0), 9))
        lag = getattr(args, ("arm" if j == 0 else "pendulum") + "_lag")
        recorded[:, j] = (1.0 + g) * first_order(times, states_on_grid[at, j], lag) + o

    rng = np.random.default_rng(args.seed)
    step = 2.0 * math.pi / COUNTS_PER_REV
    angles = recorded
    if not args.clean:
        angles = np.round((angles + rng.normal(0.0, args.noise, angles.shape)) / step) * step
    recorded_torque = torque + (rng.normal(0.0, args.torque_noise, torque.shape) if args.torque_noise > 0 else 0.0)
    with open(args.out, "w") as f:
        f.write("time_s,arm_angle_rad,pendulum_angle_rad,motor_torque_Nm\n")
        for t, (a1, a2), u in zip(times, angles, recorded_torque):
            f.write(f"{t:.2f},{a1:.6f},{a2:.6f},{u:.7f}\n")

    truth = {
        "geometry": RIG,
        "start_state": {**START, "theta0": args.theta0},
        "true_friction": {"armFriction": args.arm_friction, "pendulumFriction": args.pendulum_friction},
        "viscous_friction": {"arm": args.arm_viscous, "pendulum": args.pendulum_viscous},
        "quadratic_drag": {"arm": args.arm_drag, "pendulum": args.pendulum_drag},
        "stiffness": {"arm": args.arm_stiffness, "pendulum": args.pendulum_stiffness},
        "bias_torque": {"arm": args.arm_bias, "pendulum": args.pendulum_bias},
        "sensor": {
            j: {
                "offset": getattr(args, f"{j}_offset"),
                "gain": getattr(args, f"{j}_gain"),
                "delay": getattr(args, f"{j}_delay"),
                "lag": getattr(args, f"{j}_lag"),
            }
            for j in ("arm", "pendulum")
        },
        "motor_torque": {
            "amplitude_Nm": 0.0 if args.no_torque else args.amplitude,
            "interpolation": "linear between samples",
            "recorded_noise_std_Nm": args.torque_noise,
        },
        "sampling_hz": RATE_HZ,
        "stop_s": args.stop,
        "samples": n + 1,
        "encoder_counts_per_rev": None if args.clean else COUNTS_PER_REV,
        "noise_std_rad": 0.0 if args.clean else args.noise,
        "seed": args.seed,
        "mode_switches": stats["events"],
        "arm_stuck_s": round(stats["arm_stuck_s"], 4),
        "pendulum_stuck_s": round(stats["pendulum_stuck_s"], 4),
        "arm_sticks": stats["arm_sticks"],
        "pendulum_sticks": stats["pendulum_sticks"],
        "arm_range_rad": [float(states[:, 0].min()), float(states[:, 0].max())],
    }
    if args.compare:
        ref = np.genfromtxt(args.compare, delimiter=",", names=True)
        m = min(len(ref), len(times))
        if not np.allclose(ref["time_s"][:m], times[:m]):
            sys.exit("--compare: the record's times differ from this grid")
        d_arm = states[:m, 0] - ref["arm_angle_rad"][:m]
        d_pend = states[:m, 1] - ref["pendulum_angle_rad"][:m]
        truth["compare"] = {
            "record": args.compare,
            "samples": m,
            "rms_arm_rad": float(np.sqrt(np.mean(d_arm**2))),
            "rms_pendulum_rad": float(np.sqrt(np.mean(d_pend**2))),
            "max_arm_rad": float(np.abs(d_arm).max()),
            "max_pendulum_rad": float(np.abs(d_pend).max()),
        }
    text = json.dumps(truth, indent=1)
    if args.truth:
        with open(args.truth, "w") as f:
            f.write(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
