"""Follows campaigns through WatchCampaign, as a progress bar would, from the proto alone.

Usage: watch_client.py HOST:PORT STUBS_DIR RECORD.csv RUNS

Uploads the record, then runs RUNS campaigns one after another (the same search with
another seed each, so that each simulates), each of about 11,000 evaluations on workers,
and follows each one's stream to its end. Checks that the evaluations a client is shown
never go down and end at the result's count. Prints one line per campaign and "ok" last.
"""
import sys

import grpc

address, stubs, record, runs = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
sys.path.insert(0, stubs)
from calib.v1 import calibration_pb2 as pb  # noqa: E402
from calib.v1 import calibration_pb2_grpc as rpc  # noqa: E402

api = rpc.CalibrationStub(grpc.insecure_channel(address))


def chunks(path, size=256 * 1024):
    with open(path, "rb") as f:
        first = True
        while data := f.read(size):
            if first:
                yield pb.DatasetChunk(file_name="record.csv", time_column="time_s", data=data)
                first = False
            else:
                yield pb.DatasetChunk(data=data)


dataset = api.UploadDataset(chunks(record))
backwards = []
for seed in range(1, runs + 1):
    campaign = pb.Campaign(
        name=f"watched-{seed}",
        model="furuta",
        stop_time=5.0,
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
        window_stop=5.0,
        search=pb.Search(
            methods=["nelder-mead", "powell", "differential-evolution"],
            starts=8,
            max_evaluations=1200,
            seed=seed,
        ),
    )
    submitted = api.SubmitCampaign(pb.SubmitCampaignRequest(campaign=campaign))
    shown = [s.evaluations for s in api.WatchCampaign(pb.WatchCampaignRequest(id=submitted.id))]
    drops = [(a, b) for a, b in zip(shown, shown[1:]) if b < a]
    final = api.GetCampaign(pb.GetCampaignRequest(id=submitted.id))
    assert final.phase == pb.CAMPAIGN_PHASE_FINISHED, final.phase
    print(f"seed {seed}: {len(shown)} states, {shown[-1]} evaluations, result {final.result.evaluations}, drops {drops}")
    if drops or shown[-1] != final.result.evaluations:
        backwards.append(seed)
assert not backwards, f"evaluations went down or ended off the result in runs {backwards}"
print("ok")
