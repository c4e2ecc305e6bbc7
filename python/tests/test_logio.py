"""MCAP recording read back with the `mcap` package's own reader, replay, TUM files,
the preprocessing pipeline, evo's APE against ours, and the CLI commands."""

import json
import subprocess
import sys

import numpy as np
import pytest

import edccif


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    d = tmp_path_factory.mktemp("rec")
    sc = edccif.Scenario.paper(nodes=3).replace(steps=50)
    res = edccif.record("edc-cif", sc, seed=4, mcap=d / "run.mcap", tum_dir=d / "tum")
    return sc, res, d


def test_mcap_read_by_the_mcap_package(recorded):
    from mcap.reader import make_reader

    sc, res, d = recorded
    truth, z, x0 = sc.simulate(seed=4)
    with open(d / "run.mcap", "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        schemas = {s.name for s in summary.schemas.values()}
        assert {"foxglove.PoseInFrame", "foxglove.SceneUpdate", "edccif.Measurement"} <= schemas
        counts = {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()}
        for topic in ["/truth", "/scene", "/node0/measurement", "/node2/local", "/node1/fused"]:
            assert counts[topic] == 50, topic
        meas = {}
        times = []
        for _schema, channel, message in reader.iter_messages(topics=["/node1/measurement", "/node1/fused"]):
            payload = json.loads(message.data)
            if channel.topic == "/node1/measurement":
                times.append(message.log_time)
                meas[len(meas)] = payload
    np.testing.assert_allclose([meas[k]["z"] for k in range(50)], z[:, 1, :], rtol=0, atol=1e-12)
    assert [meas[k]["triggered"] for k in range(50)] == res.triggered[:, 1].tolist()
    assert np.all(np.diff(times) == 100_000_000)  # dt = 0.1 s in nanoseconds


def test_replay_equals_run(recorded):
    sc, res, d = recorded
    truth, z, x0 = sc.simulate(seed=4)
    t_ns, z_back, trig = edccif.read_mcap_measurements(d / "run.mcap")
    np.testing.assert_array_equal(z_back, z)
    np.testing.assert_array_equal(trig, res.triggered)
    again = edccif.replay(d / "run.mcap", sc, "edc-cif", x0=x0)
    np.testing.assert_array_equal(again.estimates, res.estimates)
    # The file stores the scenario it was made with: another one needs override=True.
    with pytest.raises(edccif.ScenarioError, match="override"):
        edccif.replay(d / "run.mcap", edccif.Scenario.paper(nodes=4))
    with pytest.raises(edccif.ShapeError, match="nodes"):
        edccif.replay(d / "run.mcap", edccif.Scenario.paper(nodes=4), override=True)


def test_mcap_errors(tmp_path, recorded):
    _, _, d = recorded
    data = (d / "run.mcap").read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.warns(UserWarning, match="truncated"):
        t_ns, z, _ = edccif.read_mcap_measurements(cut)
    full_t, full_z, _ = edccif.read_mcap_measurements(d / "run.mcap")
    assert 0 < len(t_ns) < len(full_t)
    np.testing.assert_array_equal(z, full_z[: len(t_ns)])
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap file at all")
    with pytest.raises(edccif.EdccifError, match="not an MCAP file"):
        edccif.read_mcap_measurements(bad)
    damaged = bytearray(data)
    damaged[len(data) // 2] ^= 0xFF
    (tmp_path / "damaged.mcap").write_bytes(bytes(damaged))
    with pytest.raises(edccif.EdccifError, match="MCAP input"):
        edccif.read_mcap_measurements(tmp_path / "damaged.mcap")


def test_tum_files(recorded, tmp_path):
    sc, res, d = recorded
    truth, _, _ = sc.simulate(seed=4)
    t, p, q = edccif.read_tum(d / "tum" / "truth.txt")
    np.testing.assert_allclose(p, truth[:, :3], rtol=0, atol=1e-12)
    np.testing.assert_allclose(t, 0.1 * np.arange(1, 51))
    np.testing.assert_array_equal(q, np.tile([0, 0, 0, 1.0], (50, 1)))
    t2, p2, _ = edccif.read_tum(d / "tum" / "node2.txt")
    np.testing.assert_allclose(p2, res.estimates[:, 2, :3], rtol=0, atol=1e-12)
    edccif.write_tum(tmp_path / "x.txt", t, p)
    t3, p3, _ = edccif.read_tum(tmp_path / "x.txt")
    np.testing.assert_array_equal(p3, p)
    (tmp_path / "bad.txt").write_text("0 1 2 y 0 0 0 1\n")
    with pytest.raises(edccif.EdccifError, match="line 1"):
        edccif.read_tum(tmp_path / "bad.txt")


def test_preprocess_recovers_alignment(tmp_path):
    rng = np.random.default_rng(1)
    tt = np.arange(0, 20, 0.01)  # 100 Hz motion capture
    truth = np.stack([np.cos(0.5 * tt), np.sin(0.5 * tt), 1 + 0.1 * tt], axis=1)
    edccif.write_tum(tmp_path / "truth.txt", tt, truth)
    c, s = np.cos(0.3), np.sin(0.3)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    paths = []
    for i in range(3):
        to = np.arange(0.02 * i, 20, 1 / 30)  # 30 Hz camera
        po = np.stack([np.cos(0.5 * to), np.sin(0.5 * to), 1 + 0.1 * to], axis=1)
        po = (po - [1.0, 2.0, 0.5]) @ R + rng.normal(scale=0.005, size=po.shape)  # observer's own frame
        po[100] = 0.0  # an origin outlier
        edccif.write_tum(tmp_path / f"o{i}.txt", to, po)
        paths.append(tmp_path / f"o{i}.txt")
    # A helix: a shift in time moves it rigidly, so the residual cannot pin the
    # clock offsets down; the start alignment is kept, with a warning.
    with pytest.warns(UserWarning, match="do not determine its clock offset"):
        out = edccif.preprocess(tmp_path / "truth.txt", paths)
    assert out["report"]["clock"]["sources"] == ["start"] * 3
    T = out["t"].shape[0]
    assert out["z"].shape == (T, 3, 3) and out["truth"].shape == (T, 3)
    assert abs(out["dt"] - 1 / 30) < 1e-3
    err = np.nanmean(np.linalg.norm(out["z"] - out["truth"][:, None, :], axis=2))
    assert err < 0.02, err
    assert sum(len(r["removed"]) for r in out["report"]["origin"]) >= 3


def test_evo_ape_matches_ours(recorded):
    evo_file_interface = pytest.importorskip("evo.tools.file_interface")
    from evo.core import metrics, sync

    sc, res, d = recorded
    ref = evo_file_interface.read_tum_trajectory_file(str(d / "tum" / "truth.txt"))
    est = evo_file_interface.read_tum_trajectory_file(str(d / "tum" / "node0.txt"))
    ref, est = sync.associate_trajectories(ref, est)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    truth, _, _ = sc.simulate(seed=4)
    ours = np.sqrt(np.mean(np.sum((res.estimates[:, 0, :3] - truth[:, :3]) ** 2, axis=1)))
    assert abs(ape.get_statistic(metrics.StatisticsType.rmse) - ours) < 1e-9


def _cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "edccif", *args], cwd=cwd, capture_output=True, text=True)


def test_cli_simulate_replay_preprocess(tmp_path):
    p = _cli("simulate", "--nodes", "3", "--seed", "2", "--mcap", "r.mcap", "--tum", "tum", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert (tmp_path / "r.mcap").stat().st_size > 1000 and (tmp_path / "tum" / "node0.txt").exists()
    p = _cli("replay", "r.mcap", "--algorithm", "ec-ckf", "--out", "rep.npz", "--json", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["nodes"] == 3
    p = _cli("preprocess", "--truth", "tum/truth.txt", "--observer", "tum/node0.txt", "tum/node1.txt",
             "--no-spatial", "--out", "al.npz", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["steps"] > 100
    p = _cli("replay", "missing.mcap", cwd=tmp_path)
    assert p.returncode == 2 and "missing.mcap" in p.stderr
