"""A systematic probe of the Python API with hostile arguments.

Every call of the table below starts from valid arguments and replaces one
argument at a time with each hostile value (out-of-range and huge integers,
NaN and infinities, wrong types, complex numbers). Each call either succeeds or
raises an ``edccif.EdccifError``; anything else (``OverflowError``,
``TypeError``, ``ValueError``, a ``PanicException``) escapes and is reported.
``python python/tests/hostile_probe.py`` prints the count and every escape;
``test_hostile.py`` asserts there is none.
"""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path
from typing import Any, Callable, Dict, List, Tuple

import numpy as np

import edccif
from edccif import models

INTS = [-1, -(2**63) - 1, 2**64, 2**200]
FLOATS = [math.nan, math.inf, -math.inf, -1.0]
TYPES: List[Any] = ["abc", 1 + 2j, object(), [1, "a"]]
HOSTILE: List[Any] = INTS + FLOATS + TYPES


def _sc() -> edccif.Scenario:
    return edccif.Scenario.paper(nodes=3).replace(steps=5)


def _cv_filter(cls: Callable[..., Any], **kw: Any) -> Any:
    sensor = models.LinearMeasurement([[1.0, 0.0]], [[0.01]])
    return cls(models.ConstantVelocity(1, 0.1), sensor, [0.0, 0.0], np.eye(2), **kw)


KEY = bytes(range(16))
"""A packet key (16 bytes, the shortest accepted)."""


def _probes(tmp: Path) -> List[Tuple[str, Callable[..., Any], Dict[str, Any]]]:
    sc = _sc()
    mcap = tmp / "run.mcap"
    edccif.record("edc-cif", sc, seed=0, mcap=str(mcap), compression="none")
    tum = tmp / "track.txt"
    t = np.arange(50) * 0.1
    edccif.write_tum(str(tum), t, np.c_[t, np.sin(t), np.zeros(50)])
    _, z, x0 = sc.simulate(seed=0)
    net = edccif.Network(sc, "edc-cif")
    cons = edccif.Network(sc, "ec-ckf")
    kf = _cv_filter(edccif.CKF, dt=0.1)
    et = _cv_filter(edccif.ETCIF, dt=0.1)
    node = edccif.Node(sc, "edc-cif", node=0)
    trig = edccif.SensorTrigger(sc, "edc-cif", node=0)
    mnet = edccif.ModelNetwork(
        models.ConstantVelocity(1, 0.1),
        [models.LinearMeasurement([[1.0, 0.0]], [[0.01]]), models.LinearMeasurement([[1.0, 0.0]], [[0.01]])],
        x0=[0.0, 0.0],
        P0=np.eye(2),
        dt=0.1,
    )
    xs = np.zeros((3, 2))
    ps = np.stack([np.eye(2)] * 3)
    pos = models.Position([0.1, 0.1, 0.1])
    cv = models.ConstantVelocity(1, 0.1)
    lin = models.LinearMeasurement([[1.0, 0.0]], [[0.01]])
    return [
        ("Scenario.paper", edccif.Scenario.paper, {"nodes": 3}),
        ("Scenario.simulate", sc.simulate, {"seed": 0}),
        ("Scenario.replace", sc.replace, {"delta": 0.04, "steps": 5, "consensus_iters": 2, "sigma1": 5e-4}),
        ("run", edccif.run, {"algorithm": "edc-cif", "scenario": sc, "z": z, "x0": x0, "t0": 0.0,
                             "delta": 0.04, "sigma1": 5e-4, "gate": 16.0, "trigger_seed": 1, "threads": 1,
                             "record_covariances": True, "et_policy": "optimal", "trigger": "sod",
                             "force_trigger": False, "normalised": False}),
        ("run consensus", edccif.run, {"algorithm": "ec-ckf", "scenario": sc, "z": z, "consensus_iters": 2}),
        ("monte_carlo", edccif.monte_carlo, {"scenario": sc, "algorithms": "edc-cif", "runs": 2, "seed": 0,
                                             "progress": False, "delta": 0.04}),
        ("monte_carlo faults", edccif.monte_carlo, {"scenario": sc, "algorithms": "edc-cif", "runs": 2,
                                                    "progress": False, "faults": {"message_loss": 0.1, "seed": 0}}),
        ("set_worker_threads", edccif.set_worker_threads, {"n": edccif.worker_threads()}),
        ("ci_fuse", edccif.ci_fuse, {"xs": xs, "Ps": ps, "weights": None}),
        ("ci_fuse trace", edccif.ci_fuse, {"xs": xs, "Ps": ps, "weights": "trace", "progress": False}),
        ("fuse", edccif.fuse, {"xs": xs, "Ps": ps, "rule": "ici", "weights": None,
                               "independent": (np.zeros(2), np.eye(2))}),
        ("fuse optimised", edccif.fuse, {"xs": xs, "Ps": ps, "rule": "split-ci-trace"}),
        ("run fusion", edccif.run, {"algorithm": "edc-cif", "scenario": sc, "z": z, "fusion": "split-ici"}),
        ("reproduce", edccif._edccif.reproduce, {"nodes": [3], "runs": 1, "seed": 0, "progress": False,
                                         "deltas": [0.04], "sigmas": [5e-4], "duplicates": "drop"}),
        ("encode_packet", edccif.encode_packet, {"kind": "estimate", "vector": [1.0, 2.0],
                                                 "matrix": np.eye(2), "swarm": 1, "sender": 2, "step": 3,
                                                 "round": 0, "stamp_ns": 4}),
        ("decode_packet", edccif.decode_packet, {"data": edccif.encode_packet("measurement", [1.0])}),
        ("encode_packet key", edccif.encode_packet, {"kind": "measurement", "vector": [1.0], "key": KEY}),
        ("decode_packet key", edccif.decode_packet, {"data": edccif.encode_packet("measurement", [1.0], key=KEY),
                                                     "key": KEY}),
        ("Network", edccif.Network, {"scenario": sc, "algorithm": "edc-cif", "x0": x0, "t0": 0.0,
                                     "delta": 0.04, "threads": 1}),
        ("Network.step", net.step, {"z": z[0], "dt": 0.1}),
        ("Network.step consensus", cons.step, {"z": z[0], "t": 1.0}),
        ("Network.reset_node", net.reset_node, {"i": 1, "x": x0, "P": np.eye(7)}),
        ("Network.threads", lambda value: setattr(net, "threads", value), {"value": 1}),
        ("Node", edccif.Node, {"scenario": sc, "algorithm": "edc-cif", "node": 1, "x0": x0, "delta": 0.04}),
        ("Node.local", node.local, {"z": z[0, 0], "dt": 0.1}),
        ("SensorTrigger", edccif.SensorTrigger, {"scenario": sc, "algorithm": "edc-cif", "node": 1,
                                                 "trigger_seed": 3}),
        ("SensorTrigger.decide", trig.decide, {"z": z[0, 0]}),
        ("ModelNetwork.step", mnet.step, {"z": [[0.1], None], "dt": 0.1}),
        ("ModelNetwork.run", mnet.run, {"z": [np.zeros((3, 1)), None], "dt": 0.1}),
        ("ModelNetwork.reset_node", mnet.reset_node, {"i": 0, "x": [0.0, 0.0], "P": np.eye(2)}),
        ("CKF", edccif.CKF, {"motion": cv, "sensor": lin, "x0": [0.0, 0.0],
                             "P0": np.eye(2), "dt": 0.1}),
        ("UKF", edccif.UKF, {"motion": cv, "sensor": lin, "x0": [0.0, 0.0],
                             "P0": np.eye(2), "dt": 0.1, "alpha": 1.0, "beta": 2.0, "kappa": 0.0}),
        ("ETCIF", edccif.ETCIF, {"motion": cv, "sensor": lin, "x0": [0.0, 0.0],
                                 "P0": np.eye(2), "dt": 0.1, "delta": 0.04, "sigma1": 5e-4, "sigma2": 5e-4,
                                 "gate": 16.0, "trigger_seed": 1, "trigger": "sod", "et_policy": "optimal",
                                 "normalised": False}),
        ("CKF.predict", kf.predict, {"dt": 0.1}),
        ("CKF.update", kf.update, {"z": [0.1], "R": [[0.01]]}),
        ("CKF.batch_filter", kf.batch_filter, {"zs": np.zeros((3, 1)), "dt": 0.1, "Rs": [[0.01]]}),
        ("CKF.x", lambda value: setattr(kf, "x", value), {"value": [0.0, 0.0]}),
        ("CKF.P", lambda value: setattr(kf, "P", value), {"value": np.eye(2)}),
        ("ETCIF.update", et.update, {"z": [0.1]}),
        ("ConstantVelocity", models.ConstantVelocity, {"dim": 1, "q": 0.1}),
        ("ConstantAcceleration", models.ConstantAcceleration, {"dim": 1, "q": 0.1}),
        ("RandomWalk", models.RandomWalk, {"n": 2, "q": 0.1}),
        ("CoordinatedTurn", models.CoordinatedTurn, {"q1": 0.5, "q2": 1e-4}),
        ("CoordinatedTurn2D", models.CoordinatedTurn2D, {"q1": 0.5, "q2": 1e-4}),
        ("LinearMotion", models.LinearMotion, {"F": np.eye(2), "Q": np.eye(2)}),
        ("CustomMotion", models.CustomMotion, {"f": lambda X, dt: X, "Q": np.eye(2), "n": 2}),
        ("Position", models.Position, {"sigma": [0.1, 0.1, 0.1]}),
        ("RangePitchAzimuth", models.RangePitchAzimuth, {"sensor_xyz": [0.0, 0.0, 0.0], "sigma_r": 0.1,
                                                         "sigma_a": 0.01}),
        ("RangeBearing", models.RangeBearing, {"sensor_xy": [0.0, 0.0], "sigma_r": 0.1, "sigma_b": 0.01}),
        ("BearingOnly", models.BearingOnly, {"sensor_xy": [0.0, 0.0], "sigma_b": 0.01}),
        ("RangeOnly", models.RangeOnly, {"sensor_pos": [0.0, 0.0], "sigma_r": 0.1}),
        ("LinearMeasurement", models.LinearMeasurement, {"H": [[1.0, 0.0]], "R": [[0.01]]}),
        ("CustomMeasurement", models.CustomMeasurement, {"h": lambda X: X[:, :1], "R": [[0.01]], "m": 1,
                                                         "n": 2, "angles": [0]}),
        ("record", edccif.record, {"algorithm": "edc-cif", "scenario": sc, "seed": 0, "compression": "none",
                                   "ros2": False, "tum_dir": None}),
        ("replay", edccif.replay, {"path": str(mcap), "scenario": sc, "algorithm": "edc-cif", "rate_hz": None,
                                   "noise": "message", "override": False}),
        ("read_mcap_measurements", edccif.read_mcap_measurements, {"path": str(mcap)}),
        ("write_mcap", edccif.write_mcap, {"path": str(tmp / "w.mcap"), "dt": 0.1, "fused": np.zeros((2, 3, 7)),
                                           "t0_ns": 0, "nodes": [0, 1, 2], "compression": "none"}),
        ("read_tum", edccif.read_tum, {"path": str(tum)}),
        ("write_tum", edccif.write_tum, {"path": str(tmp / "w.txt"), "t": [0.0, 1.0], "p": np.zeros((2, 3))}),
        ("preprocess", edccif.preprocess, {"truth": str(tum), "observers": [str(tum)], "rate_hz": 5.0,
                                           "spatial": False, "with_scale": False, "align": "none",
                                           "offset_window": 2.0, "residual_factor": 3.0, "duplicates": "drop"}),
        ("reliability_report", edccif.reliability_report, {"out": str(tmp / "rel.md"), "runs": 1, "seed": 0,
                                                           "nodes": [3], "robustness": False, "progress": False}),
        ("MotionModel.f", cv.f, {"x": [0.0, 0.0], "dt": 0.1}),
        ("MotionModel.Q", cv.Q, {"dt": 0.1}),
        ("MotionModel.jacobian", cv.jacobian, {"x": [0.0, 0.0], "dt": 0.1}),
        ("MeasurementModel.h", pos.h, {"x": [0.0, 0.0, 0.0]}),
        ("MeasurementModel.jacobian", pos.jacobian, {"x": [0.0, 0.0, 0.0]}),
    ]


def _is_edccif(e: BaseException) -> bool:
    return isinstance(e, edccif.EdccifError)


def run_probes(skip: Tuple[str, ...] = ()) -> Tuple[int, List[str]]:
    """Runs every probe in a temporary working directory (a hostile path such
    as "abc" may be written to); returns the number of calls and the escapes."""
    cwd = os.getcwd()
    with tempfile.TemporaryDirectory() as tmp:
        os.chdir(tmp)
        try:
            return _run(Path(tmp), skip)
        finally:
            os.chdir(cwd)


def _run(tmp: Path, skip: Tuple[str, ...]) -> Tuple[int, List[str]]:
    calls = 0
    escapes: List[str] = []
    probes = _probes(tmp)
    global PROBED
    PROBED = len(probes)
    for name, fn, base in probes:
        if name in skip:
            continue
        for arg in base:
            for bad in HOSTILE:
                kw = dict(base)
                kw[arg] = bad
                calls += 1
                try:
                    fn(**kw)
                except Exception as e:  # noqa: BLE001 - classifying every exception is the point
                    if not _is_edccif(e):
                        escapes.append(f"{name}({arg}={bad!r}): {type(e).__name__}: {str(e)[:120]}")
                except BaseException as e:  # PanicException derives from BaseException
                    escapes.append(f"{name}({arg}={bad!r}): {type(e).__name__}: {str(e)[:120]}")
                    if isinstance(e, KeyboardInterrupt):
                        raise
    return calls, escapes


PROBED = 0
"""How many entry points the last `run_probes` called."""


if __name__ == "__main__":
    n, esc = run_probes()
    print(f"{n} probes over {PROBED} entry points, {len(esc)} escapes")
    for e in esc:
        print("  ", e)
