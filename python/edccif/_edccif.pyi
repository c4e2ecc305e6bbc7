"""Type stubs of the compiled extension `edccif._edccif`."""

from os import PathLike
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt
from typing_extensions import disjoint_base, final

__version__: str

_ArrayLike = npt.ArrayLike
_F64 = npt.NDArray[np.float64]
_Bool = npt.NDArray[np.bool_]
_I8 = npt.NDArray[np.int8]
_I64 = npt.NDArray[np.int64]
_Progress = Union[None, bool, Callable[[int, int], object]]
"""``progress=``: True (a bar on a terminal, else a line on stderr at most
every 5 s), False/None, or a callable ``progress(done, total)``."""

class EdccifError(ValueError): ...
class ShapeError(EdccifError): ...
class NonFiniteError(EdccifError): ...
class NotPositiveDefiniteError(EdccifError): ...
class GraphError(EdccifError): ...
class ScenarioError(EdccifError): ...
class ParameterError(EdccifError): ...
class SizeError(ParameterError):
    """What a call would allocate does not fit in the memory available (the
    message gives the size and the limit; see docs/reliability.md)."""

class ArgumentTypeError(ParameterError, TypeError):
    """An argument has the wrong type (a ParameterError, so an EdccifError, and a TypeError)."""
class UnknownAlgorithmError(EdccifError): ...
class UnknownOptionError(EdccifError): ...
class WireFormatError(EdccifError): ...
class ModelError(EdccifError): ...

@final
class Scenario:
    @staticmethod
    def paper(nodes: int = 4) -> Scenario: ...
    @staticmethod
    def from_toml(path: Union[str, PathLike[str]]) -> Scenario: ...
    @staticmethod
    def from_toml_str(text: str, *, base_dir: Optional[Union[str, PathLike[str]]] = None) -> Scenario: ...
    @staticmethod
    def from_dict(d: Mapping[str, Any], *, base_dir: Optional[Union[str, PathLike[str]]] = None) -> Scenario: ...
    @property
    def base_dir(self) -> Optional[str]: ...
    def to_toml(self) -> str: ...
    def save_toml(self, path: Union[str, PathLike[str]]) -> None: ...
    def to_dict(self) -> Dict[str, Any]: ...
    def replace(self, **overrides: Any) -> Scenario: ...
    def simulate(self, seed: int = 0, *, progress: _Progress = None) -> Tuple[_F64, _F64, _F64]: ...
    @property
    def name(self) -> str: ...
    @property
    def nodes(self) -> int: ...
    @property
    def steps(self) -> int: ...
    @property
    def dt(self) -> float: ...
    @property
    def state_dim(self) -> int: ...
    @property
    def position_dim(self) -> Optional[int]: ...
    @property
    def meas_dim(self) -> Optional[int]: ...
    @property
    def meas_dims(self) -> List[int]: ...
    @property
    def delta(self) -> Union[float, List[float]]: ...
    @property
    def normalised(self) -> bool: ...
    @property
    def sigma1(self) -> float: ...
    @property
    def sigma2(self) -> float: ...
    @property
    def fast_trig(self) -> bool: ...
    @property
    def untriggered_closed_form(self) -> bool: ...
    @property
    def fusion(self) -> str: ...
    @property
    def model_network_reason(self) -> Optional[str]: ...
    @property
    def consensus_iters(self) -> int: ...
    @property
    def sensors(self) -> _F64: ...
    @property
    def adjacency(self) -> _Bool:
        """(N, N); SizeError when N × N does not fit (see ``neighbours``)."""
    @property
    def weights(self) -> _F64:
        """(N, N); SizeError when N × N does not fit (see ``neighbours``)."""
    @property
    def neighbours(self) -> Tuple[_I64, _I64, _F64]:
        """``(offsets, indices, weights)``: the graph and weights as CSR lists."""
    @property
    def x0(self) -> _F64: ...
    @property
    def p0(self) -> _F64: ...
    @property
    def motion(self) -> Dict[str, Any]: ...
    @property
    def measurement(self) -> Dict[str, Any]: ...
    @property
    def topology(self) -> Dict[str, Any]: ...
    def __eq__(self, value: object, /) -> bool: ...

@final
class RunResult:
    @property
    def estimates(self) -> _F64: ...
    @property
    def covariances(self) -> _F64: ...
    @property
    def triggered(self) -> _Bool: ...
    @property
    def measured(self) -> _Bool: ...
    @property
    def algorithm(self) -> str: ...
    @property
    def trigger_rate(self) -> float: ...
    @property
    def values_sent(self) -> Dict[str, int]: ...
    @property
    def guard_fallbacks(self) -> int: ...
    @property
    def gated(self) -> int: ...
    @property
    def elapsed_s(self) -> float: ...
    @property
    def steps(self) -> int: ...
    @property
    def nodes(self) -> int: ...
    @property
    def report(self) -> Optional[Dict[str, Any]]: ...

@disjoint_base
class Network:
    """A network stepping one measurement row at a time, for any scenario.

    ``Network(scenario, algorithm, x0)``: a scenario of the paper's kinds runs
    on the typed network (``step(z_k)`` with ``z_k`` (N, 3)); a per-node
    scenario (``[[nodes]]``) on the model network (``z_k`` the (Σ m_i,) row
    ``simulate`` gives, or one entry per node). Either way the steps are
    ``edccif.run``'s bit for bit. ``Network.from_models`` (or ``ModelNetwork``)
    builds it from one's own models.

    ``threads`` (option, or the ``threads`` property at any time): 1 (default)
    steps serially, n >= 2 runs each step on n threads with the same numbers bit
    for bit (a parallel step releases the GIL); worth it from about 64 nodes.
    A model network steps serially.

    >>> import numpy as np, edccif
    >>> sc = edccif.Scenario.paper(64).replace(topology="ring", steps=10)
    >>> truth, z, x0 = sc.simulate(seed=1)
    >>> a = edccif.Network(sc, "ec-ckf", x0, consensus_iters=4)
    >>> b = edccif.Network(sc, "ec-ckf", x0, consensus_iters=4, threads=2)
    >>> all(np.array_equal(a.step(zk), b.step(zk)) for zk in z)
    True
    """

    def __new__(
        cls,
        scenario: Scenario,
        algorithm: str = "edc-cif",
        x0: Optional[_ArrayLike] = None,
        *,
        adjacency: Optional[_ArrayLike] = None,
        weights: Optional[_ArrayLike] = None,
        t0: float = 0.0,
        threads: Optional[int] = None,
        **options: Any,
    ) -> Network: ...
    @property
    def threads(self) -> int:
        """Threads a step runs on (1: the serial step); settable, >= 1."""
    @threads.setter
    def threads(self, value: int) -> None: ...
    def step(
        self,
        z: Union[_ArrayLike, Sequence[Optional[_ArrayLike]]],
        links: Optional[_ArrayLike] = None,
        active: Optional[_ArrayLike] = None,
        *,
        t: Optional[float] = None,
        dt: Optional[float] = None,
    ) -> _F64: ...
    def run(
        self,
        z: Union[_ArrayLike, Sequence[Optional[_ArrayLike]]],
        *,
        t: Optional[_ArrayLike] = None,
        dt: Union[None, float, _ArrayLike] = None,
        record_covariances: bool = True,
        Rs: Optional[Sequence[Optional[_ArrayLike]]] = None,
        progress: _Progress = None,
    ) -> RunResult:
        """Runs T steps of a model network (ParameterError for the paper's kinds)."""
    @property
    def t(self) -> float: ...
    @property
    def nodes(self) -> int: ...
    @property
    def state_dim(self) -> int: ...
    @property
    def meas_dims(self) -> List[int]: ...
    @property
    def weights(self) -> _F64:
        """(N, N); SizeError when N × N does not fit (see ``neighbours``)."""
    @property
    def neighbours(self) -> Tuple[_I64, _I64, _F64]:
        """``(offsets, indices, weights)``: the graph and weights as CSR lists."""
    @staticmethod
    def from_models(
        motion: MotionModel,
        sensors: Sequence[MeasurementModel],
        algorithm: str = "edc-cif",
        *,
        x0: _ArrayLike,
        P0: _ArrayLike,
        adjacency: Optional[_ArrayLike] = None,
        weights: Optional[_ArrayLike] = None,
        dt: Optional[float] = None,
        t0: float = 0.0,
        **options: Any,
    ) -> ModelNetwork: ...
    @property
    def estimates(self) -> _F64: ...
    @property
    def covariances(self) -> _F64: ...
    @property
    def local_estimates(self) -> _F64: ...
    @property
    def triggered(self) -> _Bool: ...
    @property
    def counters(self) -> Dict[str, int]: ...
    @property
    def algorithm(self) -> str: ...
    def reset_node(self, i: int, x: _ArrayLike, P: _ArrayLike) -> None: ...

@final
class ModelNetwork(Network):
    """A ``Network`` of your own models: one motion model, per node a sensor of
    its own m. ``ModelNetwork(...)`` is ``Network.from_models(...)``."""

    def __new__(
        cls,
        motion: MotionModel,
        sensors: Sequence[MeasurementModel],
        algorithm: str = "edc-cif",
        *,
        x0: _ArrayLike,
        P0: _ArrayLike,
        adjacency: Optional[_ArrayLike] = None,
        weights: Optional[_ArrayLike] = None,
        dt: Optional[float] = None,
        t0: float = 0.0,
        **options: Any,
    ) -> ModelNetwork: ...

_Packet = Tuple[str, _F64, _F64]
_Received = Sequence[Tuple[int, _ArrayLike, _ArrayLike]]

@final
class Node:
    """One estimator node, driven one phase at a time (see docs/agents.md): any
    scenario, with the node's own sensor (per-node catalogue or referenced
    Python models, mixed sensors and rates). ``local(z)``: the node's
    measurement (``meas_dim`` values), ``None`` when nothing came (the
    untriggered step), or a row of NaN when its sensor does not measure at
    this step (``measures(t)`` is False)."""

    def __new__(
        cls,
        scenario: Scenario,
        algorithm: str = "edc-cif",
        node: int = 0,
        x0: Optional[_ArrayLike] = None,
        **options: Any,
    ) -> Node: ...
    def local(self, z: Optional[_ArrayLike] = None, dt: Optional[float] = None) -> Optional[_Packet]: ...
    def adapt(self, received: _Received) -> _Packet: ...
    def combine(self, received: _Received) -> Tuple[_F64, _F64]: ...
    def consensus_round(self, received: _Received) -> Optional[_Packet]: ...
    def reset(self, x: _ArrayLike, p: _ArrayLike) -> None: ...
    def abort_step(self) -> None: ...
    def measures(self, t: int) -> bool: ...
    @property
    def estimate(self) -> _F64: ...
    @property
    def covariance(self) -> _F64: ...
    @property
    def local_estimate(self) -> _F64: ...
    @property
    def triggered(self) -> Optional[bool]: ...
    @property
    def phase(self) -> str: ...
    @property
    def node(self) -> int: ...
    @property
    def neighbours(self) -> List[int]: ...
    @property
    def fusion(self) -> str: ...
    @property
    def rounds(self) -> int: ...
    @property
    def algorithm(self) -> str: ...
    @property
    def state_dim(self) -> int: ...
    @property
    def meas_dim(self) -> int: ...
    @property
    def counters(self) -> Dict[str, int]: ...

@final
class SensorTrigger:
    """One sensor's event trigger, run where the sensor is."""

    def __new__(
        cls,
        scenario: Scenario,
        algorithm: str = "edc-cif",
        node: int = 0,
        **options: Any,
    ) -> SensorTrigger: ...
    def decide(self, z: _ArrayLike) -> bool: ...
    @property
    def meas_dim(self) -> int: ...
    @property
    def measured(self) -> int: ...
    @property
    def sent(self) -> int: ...

@final
class MonteCarloResult:
    @property
    def labels(self) -> List[str]: ...
    @property
    def runs(self) -> int: ...
    @property
    def seed(self) -> int: ...
    @property
    def nodes(self) -> int: ...
    @property
    def steps(self) -> int: ...
    @property
    def rmse(self) -> Dict[str, _F64]: ...
    @property
    def pos_rmse(self) -> Dict[str, float]: ...
    @property
    def vel_rmse(self) -> Dict[str, float]: ...
    @property
    def pos_rmse_curve(self) -> Dict[str, _F64]: ...
    @property
    def vel_rmse_curve(self) -> Dict[str, _F64]: ...
    @property
    def trigger_rate(self) -> Dict[str, float]: ...
    @property
    def nees(self) -> Dict[str, Optional[float]]: ...
    @property
    def elapsed_median_s(self) -> Dict[str, float]: ...
    def to_dict(self) -> Dict[str, Any]: ...
    def to_json(self) -> str: ...
    def to_markdown(self) -> str: ...

def run(
    algorithm: str,
    scenario: Scenario,
    z: _ArrayLike,
    x0: Optional[_ArrayLike] = None,
    *,
    t: Optional[_ArrayLike] = None,
    t0: float = 0.0,
    dt: Optional[_ArrayLike] = None,
    record_covariances: bool = True,
    faults: Optional[Mapping[str, Any]] = None,
    progress: _Progress = None,
    threads: Optional[int] = None,
    **options: Any,
) -> RunResult:
    """Run one row over z (T, N, 3).

    ``threads`` (optional int >= 1): 1 (default) steps the network serially,
    n >= 2 runs every step on n threads with the same numbers bit for bit; it
    pays off from about 64 nodes. The GIL is released during the run.

    >>> import numpy as np, edccif
    >>> sc = edccif.Scenario.paper(64).replace(topology="ring", steps=20)
    >>> truth, z, x0 = sc.simulate(seed=0)
    >>> serial = edccif.run("edc-cif", sc, z, x0=x0)
    >>> fast = edccif.run("edc-cif", sc, z, x0=x0, threads=2)
    >>> np.array_equal(serial.estimates, fast.estimates)
    True

    ``dt`` (optional, (T,)): each step's own length in seconds (``dt[0]``: from
    ``x0`` to the first row), for rows at non-uniform times; default: the
    scenario's ``dt`` at every step.

    ``faults`` (optional dict, all keys optional): ``seed`` (int),
    ``message_loss`` (probability per directed link and step), ``dropout`` and
    ``outage`` (lists of ``(node, start, end)`` step windows), ``outlier_prob``,
    ``outlier_sigma`` (default 20). Options include ``gate`` (χ² threshold on
    the normalised innovation of triggered measurements, e.g. 16.27).
    """
    ...
def monte_carlo(
    scenario: Scenario,
    algorithms: Union[str, Sequence[Union[str, Mapping[str, Any]]]],
    runs: int = 100,
    seed: int = 0,
    progress: _Progress = True,
    *,
    threads: Optional[int] = None,
    faults: Optional[Mapping[str, Any]] = None,
    **options: Any,
) -> MonteCarloResult:
    """Monte Carlo over seeded runs (in parallel, one run per core).

    ``threads`` (n >= 2) also steps each run's network on n threads (same numbers
    bit for bit): useful only with fewer runs than cores on large networks.
    ``faults``: the dict of ``run(faults=...)``; run r injects them with the
    fault seed ``faults["seed"] + r`` (simulated with ``seed + r``).

    Ctrl-C stops the study within a step and raises ``KeyboardInterrupt``; its
    ``partial`` attribute holds the ``MonteCarloResult`` of the runs ``0..p``
    that had finished (the numbers of ``runs=p``), or None. Labels must differ.
    """
def algorithms() -> List[str]: ...
def set_worker_threads(n: int) -> None:
    """Set the number of worker threads of the Monte Carlo runs (``monte_carlo``,
    ``reproduce``, ``reliability_report``) to ``n``, once per process and before
    the first of them; the numbers do not depend on it. ``ParameterError`` for
    ``n`` outside ``1..=4 × cores`` or when the pool already runs with another size."""
def worker_threads() -> int:
    """The number of worker threads of the Monte Carlo runs."""
def triggers() -> List[str]: ...
def algorithm_name(name: str) -> str:
    """The name of an algorithm as ``algorithms()`` spells it, from any accepted
    spelling (case, surrounding space and ``_`` for ``-`` ignored: ``"EDC-CIF"``
    is ``"edc-cif"``); ``UnknownAlgorithmError`` otherwise."""
def trigger_name(name: str) -> str:
    """The name of a trigger as ``triggers()`` spells it, from any accepted
    spelling; ``UnknownOptionError`` otherwise."""
def reliability_report(
    out: str = ...,
    *,
    runs: int = 50,
    seed: int = 0,
    nodes: Sequence[int] = ...,
    soak: Optional[int] = None,
    robustness: bool = True,
    json: Optional[str] = None,
    progress: _Progress = None,
) -> str: ...
def ci_fuse(
    xs: _ArrayLike,
    Ps: _ArrayLike,
    weights: Union[None, str, _ArrayLike] = None,
    *,
    progress: _Progress = None,
) -> Tuple[_F64, _F64, _F64]: ...
def fuse(
    xs: _ArrayLike,
    Ps: _ArrayLike,
    rule: str = "ci",
    weights: Optional[_ArrayLike] = None,
    independent: Optional[Tuple[_ArrayLike, _ArrayLike]] = None,
) -> Tuple[_F64, _F64]: ...
def fusion_rules() -> List[str]: ...
def reproduce(
    nodes: List[int],
    runs: int = 100,
    seed: int = 0,
    progress: _Progress = True,
    deltas: Optional[List[float]] = None,
    sigmas: Optional[List[float]] = None,
    flight_data_dir: Optional[Union[str, PathLike[str]]] = None,
    flight_files: Optional[Sequence[Union[str, PathLike[str]]]] = None,
    duplicates: str = "drop",
) -> Tuple[str, str]: ...
def record(
    algorithm: str,
    scenario: Scenario,
    seed: int = 0,
    *,
    mcap: Union[str, PathLike[str], None] = None,
    tum_dir: Union[str, PathLike[str], None] = None,
    ros2: bool = False,
    compression: str = "zstd",
    progress: _Progress = None,
    threads: Optional[int] = None,
    **options: Any,
) -> RunResult: ...
def replay(
    path: Union[str, PathLike[str]],
    scenario: Optional[Scenario] = None,
    algorithm: Optional[str] = None,
    x0: Optional[_ArrayLike] = None,
    *,
    P0: Optional[_ArrayLike] = None,
    motion: Optional[MotionModel] = None,
    sensors: Optional[Sequence[MeasurementModel]] = None,
    measurements: Optional[Sequence[str]] = None,
    truth: Optional[str] = None,
    rate_hz: Optional[float] = None,
    frame: Optional[str] = None,
    same_frames: Optional[Sequence[str]] = None,
    noise: str = "message",
    scenario_sensors: bool = False,
    adjacency: Optional[_ArrayLike] = None,
    weights: Optional[_ArrayLike] = None,
    override: bool = False,
    threads: Optional[int] = None,
    progress: _Progress = None,
    **options: Any,
) -> RunResult: ...
def read_mcap_measurements(path: Union[str, PathLike[str]]) -> Tuple[_F64, _F64, _Bool]: ...
def write_mcap(
    path: Union[str, PathLike[str]],
    *,
    dt: float,
    fused: _ArrayLike,
    covariances: Optional[_ArrayLike] = None,
    z: Optional[_ArrayLike] = None,
    triggered: Optional[_ArrayLike] = None,
    sensors: Optional[_ArrayLike] = None,
    truth: Optional[_ArrayLike] = None,
    t0_ns: int = 0,
    nodes: Optional[Sequence[int]] = None,
    local: Optional[_ArrayLike] = None,
    ros2: bool = False,
    compression: str = "zstd",
) -> None: ...
def read_ros2(
    path: Union[str, PathLike[str]],
    measurements: Sequence[str],
    truth: Optional[str] = None,
    rate_hz: Optional[float] = None,
    max_gap_s: Optional[float] = None,
    *,
    frame: Optional[str] = None,
    same_frames: Optional[Sequence[str]] = None,
) -> Dict[str, Any]: ...
def read_tum(path: Union[str, PathLike[str]]) -> Tuple[_F64, _F64, _F64]: ...
def write_tum(path: Union[str, PathLike[str]], t: _ArrayLike, p: _ArrayLike) -> None: ...
def preprocess(
    truth: Union[str, PathLike[str]],
    observers: Sequence[Union[str, PathLike[str]]],
    rate_hz: Optional[float] = None,
    spatial: bool = True,
    with_scale: bool = False,
    *,
    align: str = "estimate",
    offsets: Optional[Dict[Union[int, str], float]] = None,
    offset_window: float = 2.0,
    residual_factor: float = 3.0,
    duplicates: str = "drop",
    progress: _Progress = None,
) -> Dict[str, Any]: ...

@final
class WirePacket:
    @property
    def kind(self) -> str: ...
    @property
    def swarm(self) -> int: ...
    @property
    def sender(self) -> int: ...
    @property
    def step(self) -> int: ...
    @property
    def round(self) -> int: ...
    @property
    def stamp_ns(self) -> int: ...
    @property
    def nbytes(self) -> int: ...
    @property
    def vector(self) -> _F64: ...
    @property
    def matrix(self) -> Optional[_F64]: ...

def encode_packet(
    kind: str,
    vector: _ArrayLike,
    matrix: Optional[_ArrayLike] = None,
    *,
    swarm: int = 0,
    sender: int = 0,
    step: int = 0,
    round: int = 0,
    stamp_ns: int = 0,
    key: Optional[bytes] = None,
) -> bytes:
    """``key`` (at least 16 bytes): append the authentication tag (HMAC-SHA256
    under ``key``, truncated to 16 bytes)."""
def decode_packet(data: bytes, *, key: Optional[bytes] = None) -> WirePacket:
    """With ``key``: the packet must carry a valid tag under it (else
    ``WireFormatError``)."""

# Models (re-exported as edccif.models).

@disjoint_base
class MotionModel:
    @property
    def n(self) -> int: ...
    def f(self, x: _ArrayLike, dt: float) -> _F64: ...
    def Q(self, dt: float) -> _F64: ...
    def jacobian(self, x: _ArrayLike, dt: float) -> _F64: ...

@final
class ConstantVelocity(MotionModel):
    def __new__(cls, dim: int, q: float) -> ConstantVelocity: ...

@final
class ConstantAcceleration(MotionModel):
    def __new__(cls, dim: int, q: float) -> ConstantAcceleration: ...

@final
class RandomWalk(MotionModel):
    def __new__(cls, n: int, q: float) -> RandomWalk: ...

@final
class CoordinatedTurn(MotionModel):
    def __new__(cls, q1: float, q2: float, *, fast_trig: bool = True) -> CoordinatedTurn: ...

@final
class CoordinatedTurn2D(MotionModel):
    def __new__(cls, q1: float, q2: float, *, fast_trig: bool = True) -> CoordinatedTurn2D: ...

@final
class LinearMotion(MotionModel):
    def __new__(cls, F: _ArrayLike, Q: _ArrayLike) -> LinearMotion: ...

@final
class CustomMotion(MotionModel):
    def __new__(
        cls,
        f: Callable[[_F64, float], _ArrayLike],
        Q: Union[_ArrayLike, Callable[[float], _ArrayLike]],
        n: int,
        jacobian: Optional[Callable[[_F64, float], _ArrayLike]] = None,
    ) -> CustomMotion: ...

@disjoint_base
class MeasurementModel:
    @property
    def m(self) -> int: ...
    @property
    def n(self) -> Optional[int]: ...
    @property
    def min_n(self) -> int: ...
    @property
    def angles(self) -> List[int]: ...
    @property
    def R(self) -> _F64: ...
    def h(self, x: _ArrayLike) -> _F64: ...
    def jacobian(self, x: _ArrayLike) -> _F64: ...

@final
class Position(MeasurementModel):
    def __new__(cls, sigma: _ArrayLike) -> Position: ...

@final
class RangePitchAzimuth(MeasurementModel):
    def __new__(
        cls, sensor_xyz: _ArrayLike, sigma_r: float, sigma_a: float, *, fast_trig: bool = True
    ) -> RangePitchAzimuth: ...

@final
class RangeBearing(MeasurementModel):
    def __new__(
        cls, sensor_xy: _ArrayLike, sigma_r: float, sigma_b: float, *, fast_trig: bool = True
    ) -> RangeBearing: ...

@final
class BearingOnly(MeasurementModel):
    def __new__(cls, sensor_xy: _ArrayLike, sigma_b: float, *, fast_trig: bool = True) -> BearingOnly: ...

@final
class RangeOnly(MeasurementModel):
    def __new__(cls, sensor_pos: _ArrayLike, sigma_r: float) -> RangeOnly: ...

@final
class LinearMeasurement(MeasurementModel):
    def __new__(cls, H: _ArrayLike, R: _ArrayLike) -> LinearMeasurement: ...

@final
class CustomMeasurement(MeasurementModel):
    def __new__(
        cls,
        h: Callable[[_F64], _ArrayLike],
        R: _ArrayLike,
        m: int,
        n: int,
        angles: Sequence[int] = ...,
        jacobian: Optional[Callable[[_F64], _ArrayLike]] = None,
    ) -> CustomMeasurement: ...

# Single filters.

@disjoint_base
class SingleFilter:
    def predict(self, dt: Optional[float] = None) -> None: ...
    def update(self, z: Optional[_ArrayLike], R: Optional[_ArrayLike] = None) -> Any: ...
    def batch_filter(
        self,
        zs: _ArrayLike,
        dt: Union[float, _ArrayLike, None] = None,
        Rs: Optional[_ArrayLike] = None,
        *,
        progress: _Progress = None,
    ) -> Tuple[_F64, _F64]: ...
    @property
    def x(self) -> _F64:
        """The estimate (n,), a read-only copy: ``kf.x[0] = 1`` raises
        ``ValueError``; assign a whole array (``kf.x = x_new``, validated)."""
    @x.setter
    def x(self, value: _ArrayLike) -> None: ...
    @property
    def P(self) -> _F64:
        """The covariance (n, n), a read-only copy: ``kf.P[0, 0] = 9`` raises
        ``ValueError``; assign a whole matrix (``kf.P = P_new``, validated)."""
    @P.setter
    def P(self, value: _ArrayLike) -> None: ...
    @property
    def dim_x(self) -> int: ...
    @property
    def dim_z(self) -> int: ...
    @property
    def dt(self) -> Optional[float]: ...

@final
class CKF(SingleFilter):
    def __new__(
        cls,
        motion: MotionModel,
        sensor: MeasurementModel,
        x0: _ArrayLike,
        P0: _ArrayLike,
        dt: Optional[float] = None,
    ) -> CKF: ...

@final
class EKF(SingleFilter):
    def __new__(
        cls,
        motion: MotionModel,
        sensor: MeasurementModel,
        x0: _ArrayLike,
        P0: _ArrayLike,
        dt: Optional[float] = None,
    ) -> EKF: ...

@final
class UKF(SingleFilter):
    def __new__(
        cls,
        motion: MotionModel,
        sensor: MeasurementModel,
        x0: _ArrayLike,
        P0: _ArrayLike,
        dt: Optional[float] = None,
        alpha: float = 1.0,
        beta: float = 2.0,
        kappa: float = 0.0,
    ) -> UKF: ...

@final
class CIF(SingleFilter):
    def __new__(
        cls,
        motion: MotionModel,
        sensor: MeasurementModel,
        x0: _ArrayLike,
        P0: _ArrayLike,
        dt: Optional[float] = None,
    ) -> CIF: ...
    @property
    def y(self) -> _F64: ...
    @property
    def Y(self) -> _F64: ...

@final
class ETCIF(SingleFilter):
    def __new__(
        cls,
        motion: MotionModel,
        sensor: MeasurementModel,
        x0: _ArrayLike,
        P0: _ArrayLike,
        dt: Optional[float] = None,
        trigger: str = "sod",
        delta: Optional[float] = None,
        sigma1: float = 5e-4,
        sigma2: float = 5e-4,
        et_policy: Optional[str] = None,
        gate: Optional[float] = None,
        trigger_seed: Optional[int] = None,
        untriggered_closed_form: bool = True,
        normalised: bool = False,
    ) -> ETCIF: ...
    def update(self, z: Optional[_ArrayLike], R: Optional[_ArrayLike] = None) -> Optional[bool]: ...
    @property
    def triggered(self) -> Optional[bool]: ...
    @property
    def batch_sent(self) -> _I8: ...
    @property
    def y(self) -> _F64: ...
    @property
    def Y(self) -> _F64: ...
