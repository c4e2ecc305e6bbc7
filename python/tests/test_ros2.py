"""ROS 2 bags: written by the independent `mcap-ros2-support` writer (zstd and lz4
chunks, CDR), replayed through `edccif replay` and the Python API, equal to the
same data fed as arrays; every supported message type; edccif's own ROS 2 topics
read back by `mcap-ros2-support`'s decoder and replayed."""

import json
import subprocess
import sys

import numpy as np
import pytest

import edccif

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
TWIST = "MSG: geometry_msgs/Twist\nVector3 linear\nVector3 angular\n"
TWC = "MSG: geometry_msgs/TwistWithCovariance\nTwist twist\nfloat64[36] covariance\n"
TRANSFORM = "MSG: geometry_msgs/Transform\nVector3 translation\nQuaternion rotation\n"
TS = "MSG: geometry_msgs/TransformStamped\nstd_msgs/Header header\nstring child_frame_id\nTransform transform\n"


def msgdef(main, *deps):
    return main + "".join(SEP + d for d in deps)


DEFS = {
    "geometry_msgs/msg/PointStamped": msgdef("std_msgs/Header header\nPoint point\n", HEADER, TIME, POINT),
    "geometry_msgs/msg/PoseStamped": msgdef("std_msgs/Header header\nPose pose\n", HEADER, TIME, POSE, POINT, QUAT),
    "geometry_msgs/msg/PoseWithCovarianceStamped": msgdef(
        "std_msgs/Header header\nPoseWithCovariance pose\n", HEADER, TIME, PWC, POSE, POINT, QUAT
    ),
    "nav_msgs/msg/Odometry": msgdef(
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n"
        "geometry_msgs/TwistWithCovariance twist\n",
        HEADER,
        TIME,
        PWC.replace("MSG: geometry_msgs/PoseWithCovariance", "MSG: geometry_msgs/PoseWithCovariance"),
        POSE,
        POINT,
        QUAT,
        TWC,
        TWIST,
        VEC3,
    ),
    "tf2_msgs/msg/TFMessage": msgdef(
        "geometry_msgs/TransformStamped[] transforms\n", TS, HEADER, TIME, TRANSFORM, VEC3, QUAT
    ),
}

T0 = 1_700_000_000_000_000_000
TOPICS = ["/drone1/target", "/drone2/target", "/drone3/target"]


def header(ns, frame):
    return {"stamp": {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}, "frame_id": frame}


def point(p):
    return {"x": float(p[0]), "y": float(p[1]), "z": float(p[2])}


def write_bag(path, z, truth, dt, compression=CompressionType.ZSTD, truth_type="geometry_msgs/msg/PointStamped"):
    """A bag as a robot would record it: one PointStamped topic per sensor, stamped
    t0 + k·dt, and a truth topic; log times a little after the stamps."""
    with open(path, "wb") as f:
        w = ros2_writer.Writer(f, compression=compression)
        ps = w.register_msgdef("geometry_msgs/msg/PointStamped", DEFS["geometry_msgs/msg/PointStamped"])
        tr = w.register_msgdef(truth_type, DEFS[truth_type])
        for k in range(z.shape[0]):
            ns = T0 + round(k * dt * 1e9)
            for i, topic in enumerate(TOPICS[: z.shape[1]]):
                if np.isfinite(z[k, i]).all():
                    msg = {"header": header(ns, "world"), "point": point(z[k, i])}
                    w.write_message(topic, ps, msg, log_time=ns + 2_000_000, publish_time=ns)
            if truth_type == "geometry_msgs/msg/PointStamped":
                msg = {"header": header(ns, "world"), "point": point(truth[k, :3])}
            else:
                msg = {
                    "header": header(ns, "world"),
                    "pose": {"position": point(truth[k, :3]), "orientation": {"x": 0, "y": 0, "z": 0, "w": 1.0}},
                }
            w.write_message("/vicon/target", tr, msg, log_time=ns + 1_000_000, publish_time=ns)
        w.finish()


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    d = tmp_path_factory.mktemp("bag")
    sc = edccif.Scenario.paper(nodes=3).replace(steps=40)
    truth, z, x0 = sc.simulate(seed=5)
    write_bag(d / "run.mcap", z, truth, sc.dt)
    sc.save_toml(d / "sc.toml")
    return sc, truth, z, x0, d


def test_zstd_bag_from_mcap_ros2_support(bag):
    from mcap.reader import make_reader

    sc, truth, z, x0, d = bag
    with open(d / "run.mcap", "rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    assert chunks and all(c.compression == "zstd" for c in chunks)
    rec = edccif.read_ros2(d / "run.mcap", TOPICS, truth="/vicon/target")
    assert rec["z"].shape == z.shape and rec["truncated"] is None
    np.testing.assert_array_equal(rec["z"], z)
    np.testing.assert_array_equal(rec["truth"], truth[:, :3])
    np.testing.assert_array_equal(rec["t_ns"], T0 + np.round(np.arange(40) * sc.dt * 1e9).astype(np.int64))
    np.testing.assert_allclose(rec["dt"][1:], sc.dt, rtol=0, atol=1e-9)
    # Frames select the messages.
    one = edccif.read_ros2(d / "run.mcap", ["/drone2/target#world"])
    np.testing.assert_array_equal(one["z"][:, 0], z[:, 1])
    with pytest.raises(edccif.EdccifError, match="no header.frame_id `cam9`"):
        edccif.read_ros2(d / "run.mcap", ["/drone2/target#cam9"])
    with pytest.raises(edccif.EdccifError, match="no message on topic `/nope`"):
        edccif.read_ros2(d / "run.mcap", ["/nope"])


def test_replay_of_the_bag_equals_the_arrays(bag):
    sc, truth, z, x0, d = bag
    direct = edccif.run("edc-cif", sc, z, x0=x0)
    # The bag's points hold range, pitch and azimuth: read as such only when told.
    with pytest.raises(edccif.ScenarioError, match="range, pitch and azimuth"):
        edccif.replay(d / "run.mcap", sc, "edc-cif", x0=x0, measurements=TOPICS)
    replayed = edccif.replay(d / "run.mcap", sc, "edc-cif", x0=x0, measurements=TOPICS, truth="/vicon/target",
                             scenario_sensors=True)
    np.testing.assert_array_equal(replayed.estimates, direct.estimates)
    np.testing.assert_array_equal(replayed.triggered, direct.triggered)
    with pytest.raises(edccif.ShapeError, match="nodes"):
        edccif.replay(d / "run.mcap", edccif.Scenario.paper(nodes=4), measurements=TOPICS, scenario_sensors=True)


def _cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "edccif", *args], cwd=cwd, capture_output=True, text=True)


def test_cli_replay_of_the_bag_equals_the_arrays(bag):
    sc, truth, z, x0, d = bag
    direct = edccif.run("ec-ckf", sc, z)
    args = ["replay", "run.mcap", "--algorithm", "ec-ckf", "--scenario", "sc.toml", "--truth", "/vicon/target"]
    for t in TOPICS:
        args += ["--measurement", t]
    p = _cli(*args, "--out", "rep.npz", cwd=d)
    assert p.returncode == 2 and "--sensor scenario" in p.stderr, p.stderr
    p = _cli(*args, "--sensor", "scenario", "--out", "rep.npz", "--json", cwd=d)
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    assert out["nodes"] == 3 and out["position_rmse_m"] > 0
    rep = np.load(d / "rep.npz")
    np.testing.assert_array_equal(rep["estimates"], direct.estimates)
    np.testing.assert_array_equal(rep["z"], z)
    np.testing.assert_array_equal(rep["truth"], truth[:, :3])
    # Without a scenario: a constant-velocity position scenario at the stamps' rate.
    p = _cli("replay", "run.mcap", "--measurement", "/drone1/target", "--truth", "/vicon/target", "--json", cwd=d)
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["steps"] == 40
    p = _cli("replay", "run.mcap", "--truth", "/vicon/target", cwd=d)
    assert p.returncode == 2 and "--measurement" in p.stderr


def test_lz4_bag_and_every_message_type(tmp_path):
    rng = np.random.default_rng(2)
    n = 12
    pos = rng.normal(size=(n, 3))
    with open(tmp_path / "types.mcap", "wb") as f:
        w = ros2_writer.Writer(f, compression=CompressionType.LZ4)
        s = {name: w.register_msgdef(name, text) for name, text in DEFS.items()}
        quat = {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}
        cov = (np.eye(6) * 0.01).ravel().tolist()
        for k in range(n):
            ns = T0 + k * 50_000_000
            p = point(pos[k])
            w.write_message("/p", s["geometry_msgs/msg/PointStamped"], {"header": header(ns, "a"), "point": p})
            w.write_message(
                "/ps", s["geometry_msgs/msg/PoseStamped"],
                {"header": header(ns, "a"), "pose": {"position": p, "orientation": quat}},
            )
            w.write_message(
                "/pwc", s["geometry_msgs/msg/PoseWithCovarianceStamped"],
                {"header": header(ns, "a"), "pose": {"pose": {"position": p, "orientation": quat}, "covariance": cov}},
            )
            zero = {"x": 0.0, "y": 0.0, "z": 0.0}
            w.write_message(
                "/odom", s["nav_msgs/msg/Odometry"],
                {
                    "header": header(ns, "a"),
                    "child_frame_id": "base_link",
                    "pose": {"pose": {"position": p, "orientation": quat}, "covariance": cov},
                    "twist": {"twist": {"linear": zero, "angular": zero}, "covariance": cov},
                },
            )
            tf = [
                {"header": header(ns, "a"), "child_frame_id": c, "transform": {"translation": t, "rotation": quat}}
                for c, t in [("other", point([9, 9, 9])), ("target", p)]
            ]
            w.write_message("/tf", s["tf2_msgs/msg/TFMessage"], {"transforms": tf})
        w.finish()
    rec = edccif.read_ros2(tmp_path / "types.mcap", ["/p", "/ps", "/pwc", "/odom", "/tf#target"])
    assert rec["z"].shape == (n, 5, 3)
    for i in range(5):
        np.testing.assert_array_equal(rec["z"][:, i], pos)
    with pytest.raises(edccif.EdccifError, match="child frame"):
        edccif.read_ros2(tmp_path / "types.mcap", ["/tf"])


def test_edccif_ros2_topics_read_by_mcap_ros2_support_and_replayed(tmp_path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    p = _cli("simulate", "--nodes", "3", "--seed", "1", "--mcap", "r.mcap", "--ros2", "--out", "run.npz", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    run = np.load(tmp_path / "run.npz")
    z = run["z"]
    with open(tmp_path / "r.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        got = [
            (m.header.stamp.sec * 10**9 + m.header.stamp.nanosec, [m.point.x, m.point.y, m.point.z])
            for _, _, _, m in reader.iter_decoded_messages(topics=["/node1/point"])
        ]
    assert [g[0] for g in got] == [round(k * 0.1e9) for k in range(len(got))]
    np.testing.assert_array_equal([g[1] for g in got], z[:, 1])
    sc = edccif.Scenario.paper(nodes=3)
    sc.save_toml(tmp_path / "sc.toml")
    args = ["replay", "r.mcap", "--scenario", "sc.toml", "--sensor", "scenario", "--truth", "/truth/point",
            "--out", "rep.npz"]
    for i in range(3):
        args += ["--measurement", f"/node{i}/point"]
    p = _cli(*args, cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    # The CLI replays from the scenario's x0 (simulate started from the drawn x̂0).
    np.testing.assert_array_equal(np.load(tmp_path / "rep.npz")["estimates"], edccif.run("edc-cif", sc, z).estimates)
    # Uncompressed on request.
    p = _cli("simulate", "--nodes", "3", "--mcap", "u.mcap", "--mcap-compression", "none", "--out", "u.npz",
             cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    with open(tmp_path / "u.mcap", "rb") as f:
        assert all(c.compression == "" for c in make_reader(f).get_summary().chunk_indexes)


def test_truncated_bag_warns_and_gives_the_messages_before_the_cut(bag, tmp_path):
    sc, truth, z, x0, d = bag
    data = (d / "run.mcap").read_bytes()
    (tmp_path / "cut.mcap").write_bytes(data[: int(len(data) * 0.98)])
    with pytest.warns(UserWarning, match="truncated"):
        rec = edccif.read_ros2(tmp_path / "cut.mcap", TOPICS)
    assert rec["truncated"] and "truncated" in rec["truncated"]
    np.testing.assert_array_equal(rec["z"], z[: rec["z"].shape[0]])


def test_write_mcap_of_one_node_of_a_distributed_run(tmp_path):
    sc = edccif.Scenario.paper(nodes=4).replace(steps=20)
    truth, z, x0 = sc.simulate(seed=3)
    res = edccif.run("edc-cif", sc, z, x0=x0)
    edccif.write_mcap(
        tmp_path / "agent3.mcap",
        dt=sc.dt,
        fused=res.estimates[:, 3:4],
        covariances=res.covariances[:, 3:4],
        z=z[:, 3:4],
        triggered=res.triggered[:, 3:4],
        sensors=sc.sensors[3:4],
        truth=truth,
        nodes=[3],
        t0_ns=T0,
    )
    t_ns, z_back, trig = edccif.read_mcap_measurements(tmp_path / "agent3.mcap")
    assert z_back.shape == (20, 4, 3) and np.isnan(z_back[:, :3]).all()
    np.testing.assert_array_equal(z_back[:, 3], z[:, 3])
    np.testing.assert_array_equal(trig[:, 3], res.triggered[:, 3])
    assert t_ns[0] == float(T0)
    with pytest.raises(edccif.ShapeError, match="covariances"):
        edccif.write_mcap(tmp_path / "x.mcap", dt=0.1, fused=res.estimates, covariances=res.covariances[:, :2])
    with pytest.raises(edccif.EdccifError, match="node_ids"):
        edccif.write_mcap(tmp_path / "x.mcap", dt=0.1, fused=res.estimates, nodes=[0, 0, 1, 2])


# ---------------------------------------------------------------- sensors at their own rates

RATES = [("/cam0/target", 30.0, 0), ("/cam1/target", 20.0, 7_000_000), ("/cam2/target", 12.5, 23_000_000)]


def _flight(t):
    """A smooth 3-D path (m) at times t (s)."""
    t = np.asarray(t, dtype=float)
    return np.stack([np.cos(0.5 * t), np.sin(0.5 * t), 1.0 + 0.1 * t], axis=-1)


@pytest.fixture(scope="module")
def multirate(tmp_path_factory):
    """A zstd bag of three PointStamped sensors at 30, 20 and 12.5 Hz with
    different phases, and a 100 Hz truth topic; plus the same data as arrays on
    the union of the stamps (NaN where a sensor has no message)."""
    d = tmp_path_factory.mktemp("multirate")
    rng = np.random.default_rng(11)
    duration_ns = 4_000_000_000
    stamps = {topic: [T0 + off + round(k * 1e9 / hz) for k in range(int(duration_ns * hz / 1e9))]
              for topic, hz, off in RATES}
    truth_ns = [T0 + k * 10_000_000 for k in range(duration_ns // 10_000_000 + 5)]
    meas = {topic: _flight((np.array(ns) - T0) * 1e-9) + rng.normal(scale=0.01, size=(len(ns), 3))
            for topic, ns in stamps.items()}
    with open(d / "multirate.mcap", "wb") as f:
        w = ros2_writer.Writer(f, compression=CompressionType.ZSTD)
        ps = w.register_msgdef("geometry_msgs/msg/PointStamped", DEFS["geometry_msgs/msg/PointStamped"])
        # In the order a recorder logs them: by arrival (a little after the stamp).
        events = [(ns + 3_000_000, topic, ns, meas[topic][j]) for topic, v in stamps.items() for j, ns in enumerate(v)]
        events += [(ns + 1_000_000, "/vicon/target", ns, _flight((ns - T0) * 1e-9)) for ns in truth_ns]
        for log, topic, ns, p in sorted(events, key=lambda e: (e[0], e[1])):
            msg = {"header": header(ns, "world"), "point": point(p)}
            w.write_message(topic, ps, msg, log_time=log, publish_time=ns)
        w.finish()
    t_ns = np.array(sorted({ns for v in stamps.values() for ns in v}), dtype=np.int64)
    z = np.full((t_ns.size, len(RATES), 3), np.nan)
    for i, (topic, _, _) in enumerate(RATES):
        rows = np.searchsorted(t_ns, stamps[topic])
        z[rows, i] = meas[topic]
    sc = edccif.Scenario.from_dict(
        {
            "name": "multirate",
            "dt": 1 / 30,
            "steps": int(t_ns.size),
            "delta": 3e-4,
            "sigma1": 5e-4,
            "sigma2": 5e-4,
            "x0": [1.0, 0.0, 1.0, 0.0, 0.5, 0.1],
            "p0_diag": [1e-2, 1e-2, 1e-2, 0.04, 0.04, 0.04],
            "sensors": [[0.0, 0.0, 0.0]] * 3,
            "motion": {"kind": "constant-velocity", "q": 0.5},
            "measurement": {"kind": "position", "sigma": [0.01] * 3},
            "topology": {"kind": "line"},
        }
    )
    sc.save_toml(d / "sc.toml")
    # dt[0]: from x0 to the first row (the scenario's dt); then the stamps' differences.
    dt = np.r_[sc.dt, np.diff(t_ns) * 1e-9]
    return sc, t_ns, z, dt, d


def test_multirate_bag_rows_are_the_union_of_the_stamps(multirate):
    sc, t_ns, z, dt, d = multirate
    rec = edccif.read_ros2(d / "multirate.mcap", [r[0] for r in RATES], truth="/vicon/target")
    np.testing.assert_array_equal(rec["t_ns"], t_ns)
    np.testing.assert_array_equal(rec["z"], z)
    # Every row has a message of at least one sensor, and every sensor misses rows.
    have = np.isfinite(z).all(axis=2)
    assert have.any(axis=1).all() and (~have).any(axis=0).all()
    assert have.sum(axis=0).tolist() == [120, 80, 50]
    # Steps of different lengths (the phases differ): at least 5 distinct ones.
    assert np.unique(np.round(np.diff(t_ns) * 1e-9, 6)).size >= 5
    # The 100 Hz truth interpolated at the rows (linear: error < 1e-4 m on this path).
    np.testing.assert_allclose(rec["truth"], _flight((t_ns - T0) * 1e-9), atol=1e-4)


def test_multirate_replay_on_stamps_equals_run_with_the_dts(multirate):
    sc, t_ns, z, dt, d = multirate
    topics = [r[0] for r in RATES]
    direct = edccif.run("edc-cif", sc, z, dt=dt)
    replayed = edccif.replay(d / "multirate.mcap", sc, "edc-cif", measurements=topics, truth="/vicon/target")
    np.testing.assert_array_equal(replayed.estimates, direct.estimates)
    np.testing.assert_array_equal(replayed.covariances, direct.covariances)
    np.testing.assert_array_equal(replayed.triggered, direct.triggered)
    # A node without a message at a step predicts over that step and still fuses:
    # its estimate moves, and differs from its prediction alone (the neighbours' information).
    est = direct.estimates
    missing = ~np.isfinite(z[1:, 2]).all(axis=1)
    moved = np.linalg.norm(est[1:, 2, :3] - est[:-1, 2, :3], axis=1)
    assert missing.sum() > 50 and (moved[missing] > 0).all()
    k = int(np.flatnonzero(missing)[10]) + 1
    pred = est[k - 1, 2, :3] + dt[k] * est[k - 1, 2, 3:]
    assert np.linalg.norm(est[k, 2, :3] - pred) > 1e-6
    # Tracking on the stamps: RMSE below 2 cm against the truth (noise 1 cm).
    err = est[:, :, :3] - _flight((t_ns - T0) * 1e-9)[:, None, :]
    assert np.sqrt(np.mean(err[20:] ** 2)) < 0.02
    # The uniform-step run of the same rows is a different (wrong-time) filter.
    assert not np.allclose(edccif.run("edc-cif", sc, z).estimates, direct.estimates, atol=1e-4)
    with pytest.raises(edccif.ShapeError, match="dt"):
        edccif.run("edc-cif", sc, z, dt=dt[:-1])
    with pytest.raises(ValueError, match="dt|time step"):
        edccif.run("edc-cif", sc, z, dt=np.r_[dt[:-1], 0.0])


def test_multirate_cli_replay_on_stamps_and_resampled(multirate):
    sc, t_ns, z, dt, d = multirate
    args = ["replay", "multirate.mcap", "--algorithm", "ec-ckf", "--json", "--scenario", "sc.toml", "--truth",
            "/vicon/target"]
    for topic, _, _ in RATES:
        args += ["--measurement", topic]
    p = _cli(*args, "--out", "stamps.npz", cwd=d)
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    assert out["timing"] == "stamps" and out["steps"] == t_ns.size and out["position_rmse_m"] < 0.02
    rep = np.load(d / "stamps.npz")
    np.testing.assert_array_equal(rep["t_ns"], t_ns)
    np.testing.assert_array_equal(rep["dt"], dt)
    np.testing.assert_array_equal(rep["estimates"], edccif.run("ec-ckf", sc, z, dt=dt).estimates)
    # --rate HZ: resampled to a uniform grid (linear interpolation), steps of 1/HZ.
    p = _cli(*args, "--rate", "25", "--out", "grid.npz", cwd=d)
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["timing"] == "resampled"
    grid = np.load(d / "grid.npz")
    rec = edccif.read_ros2(d / "multirate.mcap", [r[0] for r in RATES], rate_hz=25.0)
    assert grid["z"].shape[0] == rec["z"].shape[0] == 100
    np.testing.assert_array_equal(grid["z"], rec["z"])
    np.testing.assert_array_equal(grid["dt"], np.full(100, 1 / 25))
    np.testing.assert_array_equal(grid["estimates"], edccif.run("ec-ckf", sc, rec["z"], dt=grid["dt"]).estimates)
    # Without a scenario: the constant-velocity position scenario, still on the stamps.
    p = _cli(*args[:5], *args[7:], cwd=d)
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["steps"] == t_ns.size
