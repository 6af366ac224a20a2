"""A Calibration API client written from proto/calib/v1/calibration.proto alone.

Usage: calibration_client.py HOST:PORT STUBS_DIR RECORD.csv [CA.pem TOKEN_FILE]

With a CA and a token file, dials over TLS (trusting that CA) and presents the token as
`authorization: Bearer TOKEN` on every call; first checks that a call without the token is
refused as UNAUTHENTICATED. Uploads the record, submits a campaign on it (Nelder-Mead from two starts), follows the
campaign's stream to its end, fetches the result and checks the recovered frictions.
Prints the recovered values and "ok" last.
"""
import json
import sys

import grpc

address, stubs, record = sys.argv[1], sys.argv[2], sys.argv[3]
sys.path.insert(0, stubs)
from calib.v1 import calibration_pb2 as pb  # noqa: E402
from calib.v1 import calibration_pb2_grpc as rpc  # noqa: E402

TRUTH = {"armFriction": 0.010125, "pendulumFriction": 0.00117}

if len(sys.argv) > 5:
    with open(sys.argv[4], "rb") as f:
        ca = f.read()
    with open(sys.argv[5]) as f:
        token = f.read().strip()
    tls = grpc.ssl_channel_credentials(root_certificates=ca)
    # The certificate names localhost and 127.0.0.1.
    anonymous = rpc.CalibrationStub(grpc.secure_channel(address, tls))
    try:
        anonymous.ListCampaigns(pb.ListCampaignsRequest())
        raise AssertionError("a call without the token was answered")
    except grpc.RpcError as e:
        assert e.code() == grpc.StatusCode.UNAUTHENTICATED, e
    credentials = grpc.composite_channel_credentials(tls, grpc.access_token_call_credentials(token))
    channel = grpc.secure_channel(address, credentials)
    print("over TLS with a token; without it: UNAUTHENTICATED")
else:
    channel = grpc.insecure_channel(address)
api = rpc.CalibrationStub(channel)


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
assert len(dataset.id) == 64, dataset
assert "arm_angle_rad" in dataset.columns, dataset.columns
print(f"dataset {dataset.id[:12]}: {dataset.samples} samples, columns {list(dataset.columns)}")

campaign = pb.Campaign(
    name="python",
    model="furuta",
    stop_time=40.0,
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
    window_stop=30.0,
    search=pb.Search(methods=["nelder-mead"], starts=2, max_evaluations=400, seed=1),
)
submitted = api.SubmitCampaign(pb.SubmitCampaignRequest(campaign=campaign, idempotency_key="py-1"))
again = api.SubmitCampaign(pb.SubmitCampaignRequest(campaign=campaign, idempotency_key="py-1"))
assert again.id == submitted.id and not again.started, again

states = list(api.WatchCampaign(pb.WatchCampaignRequest(id=submitted.id)))
last = states[-1]
assert last.phase == pb.CAMPAIGN_PHASE_FINISHED, last
assert all(a.evaluations <= b.evaluations for a, b in zip(states, states[1:]))
print(f"{len(states)} states streamed, {last.evaluations} evaluations")

fetched = api.GetCampaign(pb.GetCampaignRequest(id=submitted.id))
result = json.loads(fetched.result_json)
best = result["best"]["parameters"]
for name, truth in TRUTH.items():
    error = abs(best[name] - truth) / truth
    print(f"{name} {best[name]:.6e} (truth {truth}, {100 * error:.3f}% off)")
    assert error < 0.01, (name, best[name])
assert "waterfall.svg" in fetched.plots

try:
    api.GetCampaign(pb.GetCampaignRequest(id="0" * 64))
    raise AssertionError("an unknown campaign was found")
except grpc.RpcError as e:
    assert e.code() == grpc.StatusCode.NOT_FOUND, e

listed = api.ListCampaigns(pb.ListCampaignsRequest())
assert submitted.id in [c.id for c in listed.campaigns]
print("ok")
