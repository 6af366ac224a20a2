"""A Calibration API client that reads a campaign's result from its typed fields alone.

Usage: typed_result_client.py HOST:PORT STUBS_DIR RECORD.csv

Uploads the record, submits a short campaign (Nelder-Mead from two starts), follows it to
its end and reads CampaignState.result: the best objective, the best parameters and every
run, with no JSON anywhere (result_json is not read). Prints them one per line, numbers as
Python's repr (the shortest text that reads back to the same double), for the caller to
compare with result.json:

    id <campaign id>
    best <objective> <method> <start>
    parameter <name> <value>
    run <method> <start> <objective> <evaluations> <iterations> <at_best> <label>
    runs_at_best <count> <of>
    ok
"""
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
                yield pb.DatasetChunk(file_name="furuta_clean.csv", time_column="time_s", data=data)
                first = False
            else:
                yield pb.DatasetChunk(data=data)


dataset = api.UploadDataset(chunks(record))
campaign = pb.Campaign(
    name="typed",
    model="furuta",
    stop_time=10.0,
    dataset_id=dataset.id,
    outputs=[
        pb.Output(model="armJoint.phi", measured="arm_angle_rad"),
        pb.Output(model="pendulumJoint.phi", measured="pendulum_angle_rad"),
    ],
    parameters=[
        pb.Parameter(name="armFriction", nominal=0.012, min=0.0, max=0.9),
        pb.Parameter(name="pendulumFriction", nominal=0.002, min=0.0, max=0.9),
    ],
    window_start=0.0,
    window_stop=10.0,
    search=pb.Search(methods=["nelder-mead"], starts=2, max_evaluations=120, seed=3),
)
submitted = api.SubmitCampaign(pb.SubmitCampaignRequest(campaign=campaign))
states = list(api.WatchCampaign(pb.WatchCampaignRequest(id=submitted.id)))
assert states[-1].phase == pb.CAMPAIGN_PHASE_FINISHED, states[-1]

state = api.GetCampaign(pb.GetCampaignRequest(id=submitted.id))
assert state.HasField("result"), "a finished campaign carries its typed result"
result = state.result
names = [p.name for p in result.free_parameters]
assert names == ["armFriction", "pendulumFriction"], names
assert result.version >= 1, result.version
assert result.campaign == "typed" and result.model == "furuta", (result.campaign, result.model)

best = result.best
print(f"id {submitted.id}")
print(f"best {best.objective!r} {best.method} {best.start}")
for name in names:
    print(f"parameter {name} {best.parameters[name]!r}")
assert len(result.runs) == 2, len(result.runs)
for run in result.runs:
    print(
        f"run {run.method} {run.start} {run.objective!r} {run.evaluations} {run.iterations} "
        f"{str(run.at_best).lower()} {run.label}"
    )
    assert set(run.parameters) == set(names), run.parameters
    assert run.label == f"{run.method} #{run.start}", run.label

# The best is one of the runs, at the least objective, and counted at the best by the server.
best_run = [r for r in result.runs if r.method == best.method and r.start == best.start]
assert len(best_run) == 1 and best_run[0].objective == best.objective, best_run
assert best.objective == min(r.objective for r in result.runs)
assert best_run[0].at_best
assert result.runs_at_best.count == sum(r.at_best for r in result.runs), result.runs_at_best
assert state.runs_at_best.count == result.runs_at_best.count, state.runs_at_best
assert result.from_store == result.evaluations - result.simulated
assert dict(state.best_parameters) == dict(best.parameters)
print(f"runs_at_best {result.runs_at_best.count} {result.runs_at_best.of}")
print("ok")
