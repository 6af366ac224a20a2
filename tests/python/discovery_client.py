"""A Calibration API client that asks a diagnosis to look outside the effect library.

Usage: discovery_client.py HOST:PORT STUBS_DIR RECORD.csv

RECORD.csv is a record of the driven Furuta rig with a cogging torque on the arm
(tests/python/furuta_extra_torque.py --cogging 0.006: 0.006 sin(8 phi) N m), which no
built-in effect holds. The client uploads it, calibrates the two bearing frictions, then
calls Diagnose with discover=True and reads DiagnosisState.found_outside_the_library from
its typed fields: the proposal on the arm joint, the harmonic's multiple (8, not told) and
amplitude interval (holding 0.006), each term's estimate, interval and bounds, and the refit
against the noise floor. The same figures are in report_json (diagnosis.json's
`found_outside_the_library`): the typed ones must equal them. Finally the refitted effect
(ProposalRefit.effect) is added to the campaign's defined_effects and ValidateCampaign
accepts it. Prints what it read, one item per line, then `ok`:

    proposal <name> <torque> <formula>
    harmonic <angle> <multiple> <amplitude> <ci_low> <ci_high>
    term <parameter> <estimate> <ci_low> <ci_high> <min> <max> <function>
    refit <objective_before> <objective_after> <ratio_before> <ratio_after>
    ok
"""
import json
import math
import sys

import grpc

address, stubs, record = sys.argv[1], sys.argv[2], sys.argv[3]
sys.path.insert(0, stubs)
from calib.v1 import calibration_pb2 as pb  # noqa: E402
from calib.v1 import calibration_pb2_grpc as rpc  # noqa: E402

api = rpc.CalibrationStub(grpc.insecure_channel(address))


def chunks(path, size=64 * 1024):
    with open(path, "rb") as f:
        first = True
        while True:
            data = f.read(size)
            if not data:
                return
            if first:
                yield pb.DatasetChunk(file_name="cogging.csv", time_column="time_s", data=data)
                first = False
            else:
                yield pb.DatasetChunk(data=data)


dataset = api.UploadDataset(chunks(record))
campaign = pb.Campaign(
    name="cogging",
    model="furuta",
    stop_time=20.0,
    dataset_id=dataset.id,
    outputs=[
        pb.Output(model="armJoint.phi", measured="arm_angle_rad"),
        pb.Output(model="pendulumJoint.phi", measured="pendulum_angle_rad"),
    ],
    inputs=[pb.Input(model="armTorque", measured="motor_torque_Nm")],
    parameters=[
        pb.Parameter(name="armFriction", nominal=0.012, min=1e-4, max=0.9, scale="log10"),
        pb.Parameter(name="pendulumFriction", nominal=0.002, min=1e-4, max=0.9, scale="log10"),
    ],
    window_start=0.0,
    window_stop=20.0,
    search=pb.Search(methods=["nelder-mead", "levenberg-marquardt"], starts=2, max_evaluations=400, seed=1),
    # A short diagnosis: two candidates of the library, the best refitted.
    diagnosis=pb.DiagnosisSettings(candidates=["viscous_friction.arm", "offset(armJoint.phi)"], refit=1),
)
submitted = api.SubmitCampaign(pb.SubmitCampaignRequest(campaign=campaign))
states = list(api.WatchCampaign(pb.WatchCampaignRequest(id=submitted.id)))
assert states[-1].phase == pb.CAMPAIGN_PHASE_FINISHED, states[-1]

states = list(api.Diagnose(pb.DiagnoseRequest(id=submitted.id, discover=True)))
last = states[-1]
assert last.phase == pb.CAMPAIGN_PHASE_FINISHED, (last.phase, last.failure)
assert last.HasField("found_outside_the_library"), "discovery was asked for"
found = last.found_outside_the_library
assert found.available, found.reason
assert [s.torque for s in found.searched] == ["armJoint", "pendulumJoint"], found.searched
assert len(found.proposals) == 1, [p.name for p in found.proposals]
p = found.proposals[0]
print(f"proposal {p.name} {p.torque} {p.formula}")
assert (p.name, p.torque, p.output) == ("discovered.armJoint", "armJoint", ""), p
assert "sin(8 * armJoint.phi)" in p.formula, p.formula
assert "8 periods per turn of armJoint.phi" in p.formula_words, p.formula_words
assert p.remaining_rms < p.residual_rms, (p.residual_rms, p.remaining_rms)

# The cogging: its multiple found among 1..40 (not told), its amplitude interval holding the truth.
[h] = [h for h in p.harmonics]
print(f"harmonic {h.angle} {h.multiple} {h.amplitude!r} {h.ci_low!r} {h.ci_high!r}")
assert (h.angle, h.multiple) == ("armJoint.phi", 8), h
assert h.ci_low <= 0.006 <= h.ci_high, h

for t in p.terms:
    print(f"term {t.parameter} {t.estimate!r} {t.ci_low!r} {t.ci_high!r} {t.min!r} {t.max!r} {t.function}")
    assert t.ci_low < t.estimate < t.ci_high, t
    # Bounds proposed: three half-widths of the interval on either side.
    half = (t.ci_high - t.ci_low) / 2
    assert math.isclose(t.max - t.estimate, 3 * half, rel_tol=1e-9), t
    assert math.isclose(t.estimate - t.min, 3 * half, rel_tol=1e-9), t
    assert t.words, t
assert {"a1", "b1"} <= {t.parameter for t in p.terms}, p.terms
assert "[[effects]]" in p.effects_toml and 'torque = "armJoint"' in p.effects_toml, p.effects_toml

r = p.refit
print(f"refit {r.objective_before!r} {r.objective_after!r} {r.ratio_before!r} {r.ratio_after!r}")
assert r.objective_after < 0.1 * r.objective_before, r
assert math.isclose(r.ratio_before, r.objective_before / r.noise_floor, rel_tol=1e-12), r
assert math.isclose(r.ratio_after, r.objective_after / r.noise_floor, rel_tol=1e-12), r
names = [q.name for q in r.parameters]
assert names[:2] == ["armFriction", "pendulumFriction"], names
# The harmonic refitted as an amplitude and a phase of the multiple found.
assert "discovered.armJoint.amp1" in names, names
# The effect refitted, as a campaign takes it, is the block shown.
e = r.effect
assert e.name == "discovered.armJoint" and e.torque == "armJoint", e
assert "sin(8 * armJoint.phi + phase1)" in e.formula and e.formula in r.effects_toml, (e.formula, r.effects_toml)
assert [q.name for q in e.parameters] == [n.split(".")[-1] for n in names[2:]], (e.parameters, names)
for q in e.parameters:
    assert q.min < q.nominal < q.max, q

# The typed figures are report_json's, value for value.
report = json.loads(last.report_json)["found_outside_the_library"]
assert report["available"] is True
joint = report["discovery"]["joints"][0]
assert joint["harmonics"][0]["multiple"] == h.multiple
for key in ("amplitude", "ci_low", "ci_high", "phase"):
    assert joint["harmonics"][0][key] == getattr(h, key), key
for t, j in zip(p.terms, joint["terms"]):
    assert (t.parameter, t.function) == (j["parameter"], j["function"])
    assert (t.estimate, t.ci_low, t.ci_high) == (j["estimate"], j["ci_low"], j["ci_high"]), t
refit_json = report["refits"][0]
assert (r.objective_before, r.objective_after, r.noise_floor) == (
    refit_json["objective_before"], refit_json["objective_after"], refit_json["noise_floor"])
assert r.effects_toml == refit_json["toml"]
# The refit's windows, residual, threshold and profile intervals, and what each joint's
# search looked at, are typed too: equal to report_json's.
assert len(r.stages) == len(refit_json["stages"]) > 0, r.stages
for s, j in zip(r.stages, refit_json["stages"]):
    assert [s.start, s.stop] == j["window"], (s, j)
    assert (s.objective, s.evaluations, s.method) == (j["objective"], j["evaluations"], j["method"]), (s, j)
assert [x.output for x in r.residual] == [j["output"] for j in refit_json["residual"]]
for x, j in zip(r.residual, refit_json["residual"]):
    assert (x.rms, x.lag1, x.ljung_box, x.white) == (j["rms"], j["lag1"], j["ljung_box"], j["white"]), x
assert r.threshold.delta == refit_json["threshold"]["delta"], (r.threshold, refit_json["threshold"])
assert len(r.intervals) == len(refit_json["intervals"]) > 0, r.intervals
for i, j in zip(r.intervals, refit_json["intervals"]):
    assert (i.name, i.value) == (j["name"], j["value"]), (i, j)
    for side in ("ci_low", "ci_high"):
        assert (getattr(i, side) if i.HasField(side) else None) == j[side], (side, i, j)
def same(typed, written):
    """A typed number equals the JSON's, where the JSON writes a non-finite one as null (the
    threshold above which no term enters is infinite)."""
    return typed == written or (written is None and not math.isfinite(typed))


for searched, j in zip(found.searched, report["discovery"]["joints"]):
    assert searched.torque == j["joint"] and same(searched.threshold, j["threshold"]), (searched, j)
    assert searched.unseen == (j.get("unseen") or ""), (searched, j)
    cv = j["cross_validation"]
    assert len(searched.cross_validation) == len(cv) > 0, searched
    for c, w in zip(searched.cross_validation, cv):
        assert same(c.threshold, w["threshold"]) and (c.error, c.terms) == (w["error"], w["terms"]), (c, w)
scan_json = report["harmonic_scan"]
assert found.HasField("harmonic_scan") == (scan_json is not None), scan_json
if scan_json is not None:
    assert [k.multiple for k in found.harmonic_scan.scanned] == [k["multiple"] for k in scan_json["scanned"]]
assert "## Found outside the library" in last.files["diagnosis.md"]

# Accepted into the campaign: the next run would fit it.
campaign.defined_effects.append(e)
checked = api.ValidateCampaign(pb.ValidateCampaignRequest(campaign=campaign))
assert not checked.problems, checked.problems
print("ok")
