#!/usr/bin/env python3
"""Generate the R134a property tables used by the `hx_highfi` / `hx_lowfi` models.

Writes, next to this script:

* `r134a_saturation.csv` - saturation properties on a grid uniform in ln(p),
  0.6 bar to 20 bar (400 points).
* `r134a_vapour.csv` - superheated-vapour properties on a grid uniform in ln(p)
  (48 points over the same range) times the enthalpy above saturation
  u = h - h_v(p), 0 to 160 kJ/kg (41 points).
* `r134a_check.csv` - reference values at pseudo-random points that lie between
  the grid nodes, for the interpolation test in the Rust crate.

All values in SI units (Pa, K, J/kg, kg/m^3, Pa s, W/(m K), J/(kg K), N/m),
written with 7 significant digits. Enthalpies use CoolProp's default reference
state for R134a (IIR: h = 200 kJ/kg for saturated liquid at 0 degC).

Usage: `pip install coolprop` then `python3 r134a_table.py` (deterministic: the
check points come from a seeded generator). The generated files are committed;
rerun only to change the grids.
"""

import math
import os
import random

import CoolProp
import CoolProp.CoolProp as CP

FLUID = "R134a"
HERE = os.path.dirname(os.path.abspath(__file__))

P_MIN = 0.6e5
P_MAX = 20.0e5
N_SAT = 400
N_VAP_P = 48
U_MAX = 160.0e3
N_VAP_U = 41

SAT_COLUMNS = [
    "p", "T", "rho_l", "rho_v", "h_l", "h_v",
    "mu_l", "mu_v", "k_l", "k_v", "cp_l", "cp_v", "sigma",
]
VAP_COLUMNS = ["T", "rho", "mu", "k", "cp"]


def ln_grid(n):
    a, b = math.log(P_MIN), math.log(P_MAX)
    return [math.exp(a + (b - a) * i / (n - 1)) for i in range(n)]


def sat_row(p):
    def liq(key):
        return CP.PropsSI(key, "P", p, "Q", 0, FLUID)

    def vap(key):
        return CP.PropsSI(key, "P", p, "Q", 1, FLUID)

    return [
        p, liq("T"), liq("D"), vap("D"), liq("H"), vap("H"),
        liq("V"), vap("V"), liq("L"), vap("L"), liq("C"), vap("C"), liq("I"),
    ]


def vap_row(p, u):
    h = CP.PropsSI("H", "P", p, "Q", 1, FLUID) + u
    if u == 0.0:
        # Exactly on the dew line: take the saturated-vapour side.
        return [CP.PropsSI(k, "P", p, "Q", 1, FLUID) for k in ("T", "D", "V", "L", "C")]
    return [CP.PropsSI(k, "P", p, "H", h, FLUID) for k in ("T", "D", "V", "L", "C")]


def fmt(values):
    return ",".join(f"{v:.7g}" for v in values)


def write_saturation():
    path = os.path.join(HERE, "r134a_saturation.csv")
    with open(path, "w") as f:
        f.write(f"# R134a saturation properties from CoolProp {CoolProp.__version__}, "
                f"ln(p) uniform, {N_SAT} points, SI units\n")
        f.write(",".join(SAT_COLUMNS) + "\n")
        for p in ln_grid(N_SAT):
            f.write(fmt(sat_row(p)) + "\n")


def write_vapour():
    path = os.path.join(HERE, "r134a_vapour.csv")
    with open(path, "w") as f:
        f.write(f"# R134a superheated vapour from CoolProp {CoolProp.__version__}: "
                f"{N_VAP_P} pressures ln(p) uniform {P_MIN:g}..{P_MAX:g} Pa, "
                f"{N_VAP_U} values of u = h - h_v(p) uniform 0..{U_MAX:g} J/kg, "
                f"rows p-major, SI units\n")
        f.write(f"shape,{N_VAP_P},{N_VAP_U},{P_MIN:g},{P_MAX:g},{U_MAX:g}\n")
        f.write(",".join(VAP_COLUMNS) + "\n")
        for p in ln_grid(N_VAP_P):
            for j in range(N_VAP_U):
                u = U_MAX * j / (N_VAP_U - 1)
                f.write(fmt(vap_row(p, u)) + "\n")


def write_check():
    """Points strictly inside grid cells, away from the table nodes."""
    rng = random.Random(134)
    path = os.path.join(HERE, "r134a_check.csv")
    with open(path, "w") as f:
        f.write(f"# R134a reference values from CoolProp {CoolProp.__version__} at points "
                f"off the table grids; kind sat: saturation columns, kind vap: (p, h) "
                f"then vapour columns\n")
        f.write("kind,p,h," + ",".join(SAT_COLUMNS[1:]) + "\n")
        # Saturation: log-uniform pressures over the table's span.
        for _ in range(60):
            p = math.exp(rng.uniform(math.log(P_MIN * 1.01), math.log(P_MAX * 0.99)))
            row = sat_row(p)
            f.write("sat," + fmt([p, 0.0]) + "," + fmt(row[1:]) + "\n")
        # Superheated vapour: u from 0.5 kJ/kg to just below the table's top.
        for _ in range(60):
            p = math.exp(rng.uniform(math.log(P_MIN * 1.01), math.log(P_MAX * 0.99)))
            u = rng.uniform(0.5e3, U_MAX * 0.98)
            h = CP.PropsSI("H", "P", p, "Q", 1, FLUID) + u
            vals = [CP.PropsSI(k, "P", p, "H", h, FLUID) for k in ("T", "D", "V", "L", "C")]
            pad = [0.0] * (len(SAT_COLUMNS) - 1 - len(vals))
            f.write("vap," + fmt([p, h]) + "," + fmt(vals + pad) + "\n")


if __name__ == "__main__":
    write_saturation()
    write_vapour()
    write_check()
