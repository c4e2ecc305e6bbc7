"""Replays that never give a silently wrong answer.

- Frames: a bag written by the independent `mcap-ros2-support` writer, two
  sensors publishing PoseWithCovarianceStamped in frames `map` and `odom` and a
  third in a camera frame mounted on `odom` (`/tf_static`), with a moving
  `map → odom` transform on `/tf`: the replay equals, to 1e-9, the same
  measurements transformed by hand (numpy: linear translation, slerp rotation)
  and fed as arrays to `ModelNetwork.run`; without `/tf` it is refused naming
  `map` and `odom`.
- Covariances: the messages' covariances (rotated by hand, `R Σ Rᵀ`) passed as
  per-step noise (`ModelNetwork.run(Rs=...)`) give the replay's estimate.
- A recording knows what made it: `edccif simulate --mcap` with a custom scenario
  replays bit for bit with no `--scenario`, and a different one is refused.
"""

import json
import subprocess
import sys

import numpy as np
import pytest

import edccif
from edccif import models

ros2_writer = pytest.importorskip("mcap_ros2.writer")
from mcap.writer import CompressionType  # noqa: E402

SEP = "=" * 80 + "\n"
HEADER = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
TIME = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
POINT = "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n"
QUAT = "MSG: geometry_msgs/Quaternion\nfloat64 x\nfloat64 y\nfloat64 z\nfloat64 w\n"
VEC3 = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n"
POSE = "MSG: geometry_msgs/Pose\nPoint position\nQuaternion orientation\n"
PWC = "MSG: geometry_msgs/PoseWithCovariance\nPose pose\nfloat64[36] covariance\n"
TRANSFORM = "MSG: geometry_msgs/Transform\nVector3 translation\nQuaternion rotation\n"
TS = "MSG: geometry_msgs/TransformStamped\nstd_msgs/Header header\nstring child_frame_id\nTransform transform\n"
DEFS = {
    "geometry_msgs/msg/PointStamped": "std_msgs/Header header\nPoint point\n" + SEP + HEADER + SEP + TIME + SEP + POINT,
    "geometry_msgs/msg/PoseWithCovarianceStamped": "std_msgs/Header header\nPoseWithCovariance pose\n"
    + "".join(SEP + d for d in (HEADER, TIME, PWC, POSE, POINT, QUAT)),
    "tf2_msgs/msg/TFMessage": "geometry_msgs/TransformStamped[] transforms\n"
    + "".join(SEP + d for d in (TS, HEADER, TIME, TRANSFORM, VEC3, QUAT)),
}

T0 = 1_700_000_000_000_000_000
SENSORS = [
    ("/amcl_pose", "map", 20.0, 0),
    ("/odom_pose", "odom", 15.0, 11_000_000),
    ("/cam/pose", "cam", 12.0, 23_000_000),
]
TOPICS = [s[0] for s in SENSORS]
DURATION_NS = 3_000_000_000


def _header(ns, frame):
    return {"stamp": {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}, "frame_id": frame}


def _xyz(p):
    return {"x": float(p[0]), "y": float(p[1]), "z": float(p[2])}


def _quat(q):
    return {"x": float(q[0]), "y": float(q[1]), "z": float(q[2]), "w": float(q[3])}


# ---------------------------------------------------------------- rotations by hand (numpy)


def q_mul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz])


def q_rot(q):
    """Rotation matrix of a unit quaternion (x, y, z, w)."""
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def q_axis(axis, angle):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    return np.r_[a * np.sin(angle / 2), np.cos(angle / 2)]


def slerp(a, b, s):
    if a @ b < 0:
        b = -b
    th = np.arccos(np.clip(a @ b, -1.0, 1.0))
    if th < 1e-12:
        q = (1 - s) * a + s * b
    else:
        q = (np.sin((1 - s) * th) * a + np.sin(s * th) * b) / np.sin(th)
    return q / np.linalg.norm(q)


# ---------------------------------------------------------------- the bag

TF_NS = [T0 - 50_000_000 + k * 100_000_000 for k in range(31)]  # 10 Hz, from before the first message


def map_odom(ns):
    """The moving map → odom transform at a /tf stamp: (translation, quaternion)."""
    t = (ns - T0) * 1e-9
    q = q_mul(q_axis([0, 0, 1], 0.4 + 0.35 * t), q_axis([1, 0, 0], 0.05 * np.sin(2 * t)))
    return np.array([1.0 + 0.5 * t, -0.3 + 0.2 * np.sin(t), 0.05 * t]), q


MOUNT = (np.array([0.2, -0.1, 0.5]), q_mul(q_axis([0, 0, 1], np.pi / 2), q_axis([0, 1, 0], 0.3)))  # odom → cam


def target(t):
    """The target's true path in `map` at times t (s)."""
    t = np.asarray(t, float)
    return np.stack([2 + np.cos(0.6 * t), np.sin(0.6 * t), 1.0 + 0.1 * t], axis=-1)


def map_from(frame, ns):
    """(R, t) taking points of `frame` into `map` at stamp ns, by hand: /tf
    interpolated (translation linearly, rotation by slerp), /tf_static fixed."""
    if frame == "map":
        return np.eye(3), np.zeros(3)
    j = int(np.searchsorted(TF_NS, ns, side="right")) - 1
    if TF_NS[j] == ns:
        t, q = map_odom(ns)
    else:
        s = (ns - TF_NS[j]) / (TF_NS[j + 1] - TF_NS[j])
        (ta, qa), (tb, qb) = map_odom(TF_NS[j]), map_odom(TF_NS[j + 1])
        t, q = (1 - s) * ta + s * tb, slerp(qa, qb, s)
    r_mo = q_rot(q)
    if frame == "odom":
        return r_mo, t
    r_oc = q_rot(MOUNT[1])
    return r_mo @ r_oc, r_mo @ MOUNT[0] + t


def cov_of(rng):
    a = rng.normal(scale=0.02, size=(3, 3))
    return a @ a.T + np.diag([4e-4, 3e-4, 9e-4])


def write_frames_bag(path, with_tf=True, unknown=False, invalid=False):
    """The bag; returns every sensor message as (topic, ns, frame, p_frame, cov_frame)."""
    rng = np.random.default_rng(7)
    sent = []
    with open(path, "wb") as f:
        w = ros2_writer.Writer(f, compression=CompressionType.ZSTD)
        pwc = w.register_msgdef("geometry_msgs/msg/PoseWithCovarianceStamped",
                                DEFS["geometry_msgs/msg/PoseWithCovarianceStamped"])
        tfm = w.register_msgdef("tf2_msgs/msg/TFMessage", DEFS["tf2_msgs/msg/TFMessage"])
        pts = w.register_msgdef("geometry_msgs/msg/PointStamped", DEFS["geometry_msgs/msg/PointStamped"])
        events = []
        for topic, frame, hz, off in SENSORS:
            stamps = [T0 + off + round(k * 1e9 / hz) for k in range(int(DURATION_NS * hz / 1e9))]
            if topic == "/odom_pose":
                stamps.append(TF_NS[-1] + 30_000_000)  # after the last /tf sample: dropped
            for k, ns in enumerate(stamps):
                r, t = map_from(frame, min(ns, TF_NS[-1]))
                p_map = target((ns - T0) * 1e-9) + rng.normal(scale=0.01, size=3)
                p = r.T @ (p_map - t)  # the same point in the message's frame
                cov = cov_of(rng)
                c36 = np.zeros((6, 6))
                c36[:3, :3] = cov
                c36[3:, 3:] = np.eye(3) * 0.1
                if unknown and topic == "/amcl_pose" and k % 3 == 0:
                    c36[:] = 0.0
                if invalid and topic == "/cam/pose" and k == 4:
                    c36[2, 2] = -0.5
                msg = {"header": _header(ns, frame), "pose": {
                    "pose": {"position": _xyz(p), "orientation": _quat([0, 0, 0.6, 0.8])},
                    "covariance": c36.ravel().tolist()}}
                events.append((ns + 2_000_000, topic, pwc, msg))
                sent.append((topic, ns, frame, p, None if not c36[:3, :3].any() else c36[:3, :3].copy()))
        if with_tf:
            for ns in TF_NS:
                t, q = map_odom(ns)
                tf = [{"header": _header(ns, "map"), "child_frame_id": "odom",
                       "transform": {"translation": _xyz(t), "rotation": _quat(q)}}]
                events.append((ns + 1_000_000, "/tf", tfm, {"transforms": tf}))
        static = [{"header": _header(T0, "odom"), "child_frame_id": "cam",
                   "transform": {"translation": _xyz(MOUNT[0]), "rotation": _quat(MOUNT[1])}}]
        events.append((T0 - 100_000_000, "/tf_static", tfm, {"transforms": static}))
        for k in range(149):  # 50 Hz, within the /tf span
            ns = T0 - 10_000_000 + k * 20_000_000
            r, t = map_from("odom", ns)
            events.append((ns + 500_000, "/truth", pts, {"header": _header(ns, "odom"),
                                                          "point": _xyz(r.T @ (target((ns - T0) * 1e-9) - t))}))
        for log, topic, schema, msg in sorted(events, key=lambda e: (e[0], e[1])):
            w.write_message(topic, schema, msg, log_time=log, publish_time=log)
        w.finish()
    return sent


def by_hand(sent, model_r=None):
    """The rows in `map`: union of the kept stamps, z (T, 3, 3), the rotated
    covariances (T, 3, 3, 3) (model_r where a node has none), dt."""
    kept = [(tp, ns, fr, p, c) for tp, ns, fr, p, c in sent if ns <= TF_NS[-1]]
    t_ns = np.array(sorted({ns for _, ns, *_ in kept}), dtype=np.int64)
    z = np.full((t_ns.size, 3, 3), np.nan)
    covs = np.tile(np.eye(3) * (1e-4 if model_r is None else 1.0), (t_ns.size, 3, 1, 1))
    if model_r is not None:
        covs[:] = model_r
    for topic, ns, frame, p, c in kept:
        i, row = TOPICS.index(topic), int(np.searchsorted(t_ns, ns))
        r, t = map_from(frame, ns)
        z[row, i] = r @ p + t
        if c is not None:
            rc = r @ c @ r.T
            covs[row, i] = (rc + rc.T) / 2
    d = np.diff(t_ns) * 1e-9
    dt = np.r_[np.median(d), d]
    return t_ns, z, covs, dt


X0 = np.array([3.0, 0.0, 1.0, 0.0, 0.6, 0.1])
P0 = np.diag([0.01, 0.01, 0.01, 0.04, 0.04, 0.04])


def _network():
    return edccif.ModelNetwork(models.ConstantVelocity(3, 0.5), [models.Position([0.01] * 3)] * 3, "edc-cif",
                               x0=X0, P0=P0)


def _replay(path, **kw):
    return edccif.replay(path, motion=models.ConstantVelocity(3, 0.5), sensors=[models.Position([0.01] * 3)] * 3,
                         x0=X0, P0=P0, measurements=TOPICS, truth="/truth", **kw)


@pytest.fixture(scope="module")
def frames_bag(tmp_path_factory):
    d = tmp_path_factory.mktemp("frames")
    sent = write_frames_bag(d / "frames.mcap")
    write_frames_bag(d / "no_tf.mcap", with_tf=False)
    return d, sent


def test_positions_are_brought_into_one_frame_as_by_hand(frames_bag):
    d, sent = frames_bag
    t_ns, z, covs, dt = by_hand(sent)
    rec = edccif.read_ros2(d / "frames.mcap", TOPICS, truth="/truth")
    assert rec["frame"] == "map"
    np.testing.assert_array_equal(rec["t_ns"], t_ns)
    np.testing.assert_allclose(rec["z"], z, rtol=0, atol=1e-9)
    # The truth, in odom at 50 Hz, is brought into map too (and matches the path).
    known = np.isfinite(rec["truth"][:, 0])
    assert known.all()
    np.testing.assert_allclose(rec["truth"], target((t_ns - T0) * 1e-9), atol=2e-3)
    # Covariances rotated: R Σ Rᵀ.
    have = np.isfinite(rec["cov"][:, :, 0, 0])
    np.testing.assert_allclose(rec["cov"][have], covs[have], rtol=0, atol=1e-12)
    # Every transform the report names, and the dropped message.
    src = {s["source"]: s for s in rec["report"]["sources"]}
    assert src["/amcl_pose"]["frames"][0]["transforms"] == []
    odom = src["/odom_pose"]["frames"][0]["transforms"]
    assert [(e["parent"], e["child"], e["topic"], e["fixed"]) for e in odom] == [("map", "odom", "/tf", False)]
    cam = src["/cam/pose"]["frames"][0]["transforms"]
    assert [(e["parent"], e["child"], e["topic"]) for e in cam] == [
        ("odom", "cam", "/tf_static"), ("map", "odom", "/tf")
    ]
    assert src["/odom_pose"]["dropped"] == 1 and rec["report"]["dropped"] == 1


def test_replay_equals_the_hand_transformed_arrays(frames_bag):
    d, sent = frames_bag
    t_ns, z, covs, dt = by_hand(sent)
    zs = [z[:, i] for i in range(3)]
    # Model noise: the positions alone.
    rep = _replay(d / "frames.mcap", noise="scenario")
    direct = _network().run(zs, dt=dt)
    np.testing.assert_allclose(rep.estimates, direct.estimates, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(rep.triggered, direct.triggered)
    # The messages' covariances (the default) = those covariances as per-step noise.
    rep_msg = _replay(d / "frames.mcap")
    direct_msg = _network().run(zs, dt=dt, Rs=[covs[:, i] for i in range(3)])
    np.testing.assert_allclose(rep_msg.estimates, direct_msg.estimates, rtol=0, atol=1e-9)
    np.testing.assert_allclose(rep_msg.covariances, direct_msg.covariances, rtol=0, atol=1e-12)
    assert np.abs(rep_msg.estimates - rep.estimates).max() > 1e-4  # the noise matters
    r = rep_msg.report
    assert r["input"]["frame"] == "map" and r["truth_same_frame"] is True
    assert [n["noise"] for n in r["input"]["noise"]] == ["message"] * 3
    assert [n["from_messages"] for n in r["input"]["noise"]] == [60, 45, 36]
    assert len(r["per_node"]) == 3 and all(0 < p["trigger_rate"] <= 1 for p in r["per_node"])
    truth = edccif.read_ros2(d / "frames.mcap", TOPICS, truth="/truth")["truth"]
    err = rep_msg.estimates[:, :, :3] - truth[:, None]
    assert r["position_rmse_m"] == pytest.approx(np.sqrt(np.mean(np.sum(err ** 2, axis=2))), rel=1e-12)
    assert r["position_rmse_m"] < 0.05


def test_without_tf_the_replay_is_refused_naming_map_and_odom(frames_bag):
    d, _ = frames_bag
    with pytest.raises(edccif.EdccifError, match=r"`odom`.*`map`|`map`.*`odom`") as e:
        _replay(d / "no_tf.mcap")
    assert "missing link" in str(e.value) and "/odom_pose" in str(e.value)
    # Declaring the two frames one (an identity transform) is the user's explicit choice.
    rec = edccif.read_ros2(d / "no_tf.mcap", TOPICS[:2], same_frames=["odom=map"])
    assert rec["report"]["sources"][1]["frames"][0]["transforms"][0]["topic"] == "declared"


def test_another_target_frame(frames_bag):
    d, sent = frames_bag
    rec = edccif.read_ros2(d / "frames.mcap", TOPICS, frame="odom")
    assert rec["frame"] == "odom"
    t_ns, z_map, _, _ = by_hand(sent)
    # The same points, expressed in odom.
    for row in (3, 40, 100):
        r, t = map_from("odom", int(t_ns[row]))
        have = np.isfinite(z_map[row, :, 0])
        np.testing.assert_allclose(rec["z"][row, have], (z_map[row, have] - t) @ r, atol=1e-9)


def test_unknown_covariances_fall_back_with_one_warning(tmp_path):
    sent = write_frames_bag(tmp_path / "u.mcap", unknown=True)
    with pytest.warns(UserWarning, match="unknown covariance") as rec:
        rep = _replay(tmp_path / "u.mcap")
    assert len([w for w in rec if "unknown covariance" in str(w.message)]) == 1  # once per topic
    noise = rep.report["input"]["noise"][0]
    assert noise["unknown_fallbacks"] == 20 and noise["from_messages"] == 40
    t_ns, z, covs, dt = by_hand(sent, model_r=None)
    # The unknown ones take the model's R (σ = 0.01 m): by_hand gives them 1e-4 I.
    assert sum(1 for s in sent if s[0] == "/amcl_pose" and s[4] is None) == 20
    direct = _network().run([z[:, i] for i in range(3)], dt=dt, Rs=[covs[:, i] for i in range(3)])
    np.testing.assert_allclose(rep.estimates, direct.estimates, rtol=0, atol=1e-9)


def test_an_invalid_covariance_is_refused_unless_the_model_noise_is_chosen(tmp_path):
    write_frames_bag(tmp_path / "bad.mcap", invalid=True)
    with pytest.raises(edccif.ParameterError, match="not positive definite.*noise=scenario"):
        _replay(tmp_path / "bad.mcap")
    rep = _replay(tmp_path / "bad.mcap", noise="scenario")
    assert rep.report["input"]["noise"][2]["noise"] == "model"
    sigma = _replay(tmp_path / "bad.mcap", noise="0.02")
    assert sigma.report["input"]["noise"][0]["noise"] == "sigma"


def test_positions_are_not_read_as_range_pitch_azimuth(frames_bag):
    d, _ = frames_bag
    sc = edccif.Scenario.paper(nodes=3)
    with pytest.raises(edccif.ScenarioError, match="range, pitch and azimuth.*position"):
        edccif.replay(d / "frames.mcap", sc, measurements=TOPICS)
    # Said explicitly: the scenario's sensors read the messages (and nothing is transformed then).
    with pytest.raises(edccif.EdccifError, match="cannot be transformed"):
        edccif.replay(d / "frames.mcap", sc, measurements=TOPICS, scenario_sensors=True)
    rep = edccif.replay(d / "frames.mcap", sc, measurements=TOPICS[:1] * 3, scenario_sensors=True)
    assert rep.report["input"]["noise"][0]["noise"] == "model"


def test_default_models_and_the_cli_report(frames_bag):
    d, _ = frames_bag
    rep = edccif.replay(d / "frames.mcap", measurements=TOPICS, truth="/truth")
    assert rep.report["models"].startswith("default: motion ConstantVelocity")
    assert rep.report["x0"].startswith("from the first rows")
    args = ["replay", "frames.mcap", "--motion", "cv3", "--truth", "/truth"]
    for t in TOPICS:
        args += ["--measurement", t]
    p = _cli(*args, "--json", cwd=d)
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    assert out["input"]["frame"] == "map" and out["input"]["dropped"] == 1
    assert out["truth_same_frame"] is True and out["offsets"].startswith("none")
    assert len(out["per_node"]) == 3
    p = _cli(*args, cwd=d)
    assert p.returncode == 0, p.stderr
    assert "map → odom (/tf, interpolated" in p.stdout and "odom → cam (/tf_static, fixed)" in p.stdout
    assert "same frame as the estimates: yes" in p.stdout and "trigger rate" in p.stdout
    p = _cli(*args[:2], "--measurement", TOPICS[1], "--measurement", TOPICS[0], cwd=d)
    assert p.returncode == 0 and "frame             odom" in p.stdout, p.stdout
    p = _cli("replay", "no_tf.mcap", *args[2:], cwd=d)
    assert p.returncode == 2 and "`odom`" in p.stderr and "`map`" in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1


def _cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "edccif", *args], cwd=cwd, capture_output=True, text=True)


# ---------------------------------------------------------------- stored runs

CUSTOM = """
name = "custom-3"
dt = 0.05
steps = 60
delta = 0.02
sigma1 = 0.0005
sigma2 = 0.0005
x0 = [4.0, 1.0, 1.0, 0.5, 1.0, 0.0, 0.2]
p0_diag = [0.02, 0.02, 0.02, 0.01, 0.01, 0.01, 0.0001]
sensors = [[12.0, 0.0, 1.0], [-6.0, 9.0, 4.0], [-5.0, -11.0, 0.0]]
topology = { kind = "line" }
motion = { kind = "coordinated-turn", q1 = 0.3, q2 = 0.0001 }
measurement = { kind = "range-pitch-azimuth", sigma_r = 0.2, sigma_a = 0.02 }
"""


def test_a_recording_replays_bit_for_bit_without_its_scenario(tmp_path):
    (tmp_path / "custom.toml").write_text(CUSTOM)
    p = _cli("simulate", "--scenario", "custom.toml", "--algorithm", "ec-ckf", "--seed", "3",
             "--mcap", "run.mcap", "--out", "run.npz", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    run = np.load(tmp_path / "run.npz")
    p = _cli("replay", "run.mcap", "--out", "rep.npz", "--json", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    assert out["algorithm"] == "ec-ckf" and out["stored"]["scenario"] == "stored" and out["stored"]["seed"] == 3
    np.testing.assert_array_equal(np.load(tmp_path / "rep.npz")["estimates"], run["estimates"])
    # Another scenario is refused, naming --override; with it, it runs.
    edccif.Scenario.paper(nodes=3).save_toml(tmp_path / "paper3.toml")
    p = _cli("replay", "run.mcap", "--scenario", "paper3.toml", cwd=tmp_path)
    assert p.returncode == 2 and "--override" in p.stderr and "sensors" in p.stderr, p.stderr
    p = _cli("replay", "run.mcap", "--scenario", "paper3.toml", "--override", "--json", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["stored"]["scenario"] == "given (override)"
    # The same scenario given explicitly is accepted.
    p = _cli("replay", "run.mcap", "--scenario", "custom.toml", "--json", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    # Models instead of the stored scenario: refused unless --override.
    p = _cli("replay", "run.mcap", "--motion", "cv3", cwd=tmp_path)
    assert p.returncode == 2 and "--override" in p.stderr


def test_the_built_in_scenario_replays_bit_for_bit(tmp_path):
    p = _cli("simulate", "--mcap", "r.mcap", "--out", "run.npz", "--seed", "5", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    p = _cli("replay", "r.mcap", "--out", "rep.npz", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert "stored run        yes" in p.stdout
    replayed, run = np.load(tmp_path / "rep.npz"), np.load(tmp_path / "run.npz")
    np.testing.assert_array_equal(replayed["estimates"], run["estimates"])


def test_stored_options_and_seed_in_python(tmp_path):
    sc = edccif.Scenario.paper(nodes=4).replace(steps=50)
    res = edccif.record("edc-cif", sc, seed=9, mcap=tmp_path / "s.mcap", trigger="stochastic", trigger_seed=4)
    rep = edccif.replay(tmp_path / "s.mcap")
    np.testing.assert_array_equal(rep.estimates, res.estimates)
    np.testing.assert_array_equal(rep.triggered, res.triggered)
    # A given option replaces the stored one.
    other = edccif.replay(tmp_path / "s.mcap", trigger_seed=5)
    assert not np.array_equal(other.triggered, res.triggered)


def test_a_file_without_a_stored_run_needs_a_scenario_or_models(tmp_path):
    sc = edccif.Scenario.paper(nodes=3).replace(steps=20)
    truth, z, x0 = sc.simulate(seed=1)
    res = edccif.run("edc-cif", sc, z, x0=x0)
    edccif.write_mcap(tmp_path / "w.mcap", dt=sc.dt, fused=res.estimates, z=z)
    with pytest.raises(edccif.ScenarioError, match="no default geometry"):
        edccif.replay(tmp_path / "w.mcap")
    back = edccif.replay(tmp_path / "w.mcap", sc, x0=x0)
    np.testing.assert_array_equal(back.estimates, res.estimates)
    p = _cli("replay", "w.mcap", cwd=tmp_path)
    assert p.returncode == 2 and "no default geometry" in p.stderr


# ---------------------------------------------------------------- per-step noise


def test_model_network_per_step_noise():
    rng = np.random.default_rng(0)
    z = rng.normal(size=(30, 3))
    r = np.diag(np.square([0.2, 0.3, 0.1]))  # the same bits as Position([0.2, 0.3, 0.1])'s R
    a = edccif.ModelNetwork(models.ConstantVelocity(3, 0.5), [models.Position([0.01] * 3)], "dc-cif", x0=np.zeros(6),
                            P0=np.eye(6), dt=0.1).run([z], Rs=[r])
    b = edccif.ModelNetwork(models.ConstantVelocity(3, 0.5), [models.Position([0.2, 0.3, 0.1])], "dc-cif",
                            x0=np.zeros(6), P0=np.eye(6), dt=0.1).run([z])
    np.testing.assert_array_equal(a.estimates, b.estimates)
    net = edccif.ModelNetwork(models.ConstantVelocity(3, 0.5), [models.Position([0.01] * 3)], x0=np.zeros(6),
                              P0=np.eye(6), dt=0.1)
    bad = np.tile(r, (30, 1, 1))
    bad[7, 2, 2] = -1.0
    with pytest.raises(edccif.EdccifError, match="step 7.*node 0"):
        net.run([z], Rs=[bad])
    assert np.array_equal(net.estimates, np.zeros((1, 6)))  # unchanged
    with pytest.raises(edccif.ShapeError, match="Rs"):
        net.run([z], Rs=[r, r])
    with pytest.raises(edccif.ShapeError, match="Rs"):
        net.run([z], Rs=[bad[:5]])


# ---------------------------------------------------------------- the docs

ROOT = __import__("pathlib").Path(__file__).resolve().parents[2]


def _doc_blocks(name):
    import re

    return re.findall(r"^```python\n(.*?)^```", (ROOT / "docs" / name).read_text(), flags=re.S | re.M)


@pytest.mark.parametrize("doc", ["formats.md", "realworld.md"])
def test_the_docs_replay_examples_run(doc, tmp_path, monkeypatch, capsys):
    blocks = _doc_blocks(doc)
    assert any("edccif.replay" in b for b in blocks), f"{doc} has no runnable replay example"
    monkeypatch.chdir(tmp_path)
    for i, b in enumerate(blocks):
        exec(compile(b, f"docs/{doc}: python block {i}", "exec"), {"__name__": "__docs__"})
    out = capsys.readouterr().out
    if doc == "realworld.md":
        assert "map odom [('map', 'odom', '/tf')]" in out and "['message', 'message']" in out
    else:
        assert "--override" in out


def test_the_readme_replay_example_uses_a_position_model():
    line = next(x for x in (ROOT / "README.md").read_text().splitlines() if "edccif replay BAG" in x)
    assert "--motion cv3" in line and "--frame" in line
