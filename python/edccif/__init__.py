"""edccif: communication-efficient distributed state estimation.

Event-triggered diffusion cubature information filtering with covariance
intersection (EDC-CIF) and the baselines of its paper, with a Rust core.

>>> import edccif
>>> sc = edccif.Scenario.paper(nodes=4)
>>> truth, z, x0 = sc.simulate(seed=0)
>>> res = edccif.run("edc-cif", sc, z, x0=x0)
>>> res.estimates.shape
(200, 4, 7)
"""

from . import models
from ._edccif import (
    CIF,
    CKF,
    EKF,
    ETCIF,
    UKF,
    ArgumentTypeError,
    EdccifError,
    GraphError,
    ModelError,
    ModelNetwork,
    MonteCarloResult,
    Network,
    Node,
    NonFiniteError,
    NotPositiveDefiniteError,
    ParameterError,
    RunResult,
    Scenario,
    ScenarioError,
    SensorTrigger,
    ShapeError,
    SingleFilter,
    SizeError,
    UnknownAlgorithmError,
    UnknownOptionError,
    WireFormatError,
    WirePacket,
    __version__,
    algorithm_name,
    algorithms,
    ci_fuse,
    decode_packet,
    encode_packet,
    fuse,
    fusion_rules,
    monte_carlo,
    preprocess,
    read_mcap_measurements,
    read_ros2,
    read_tum,
    record,
    reliability_report,
    replay,
    run,
    set_worker_threads,
    trigger_name,
    triggers,
    worker_threads,
    write_mcap,
    write_tum,
)

ALGORITHMS = tuple(algorithms())
"""The algorithm rows, in the paper's table order."""

FUSION_RULES = tuple(fusion_rules())
"""The fusion rule names accepted by ``fusion=`` (``run``, ``Network``,
``ModelNetwork``, ``monte_carlo``, a scenario's ``fusion``) and by ``fuse``
(equations, sources and guarantees in ``docs/fusion.md``)."""

TRIGGERS = tuple(triggers())
"""The trigger names accepted by ``trigger=`` on ``run``, ``monte_carlo`` and
``Network`` (each reads ``delta`` as its threshold, one number or one per node;
``normalised=True`` puts the send-on-delta family's in units of each sensor's
noise; see ``docs/triggers.md``)."""

__all__ = [
    "ALGORITHMS",
    "CIF",
    "CKF",
    "EKF",
    "ETCIF",
    "FUSION_RULES",
    "TRIGGERS",
    "UKF",
    "ArgumentTypeError",
    "EdccifError",
    "GraphError",
    "ModelError",
    "ModelNetwork",
    "MonteCarloResult",
    "Network",
    "Node",
    "NonFiniteError",
    "NotPositiveDefiniteError",
    "ParameterError",
    "RunResult",
    "Scenario",
    "ScenarioError",
    "SensorTrigger",
    "ShapeError",
    "SingleFilter",
    "SizeError",
    "UnknownAlgorithmError",
    "UnknownOptionError",
    "WireFormatError",
    "WirePacket",
    "__version__",
    "algorithm_name",
    "algorithms",
    "ci_fuse",
    "decode_packet",
    "encode_packet",
    "fuse",
    "fusion_rules",
    "models",
    "monte_carlo",
    "preprocess",
    "read_mcap_measurements",
    "read_ros2",
    "read_tum",
    "record",
    "reliability_report",
    "replay",
    "write_mcap",
    "run",
    "set_worker_threads",
    "trigger_name",
    "triggers",
    "worker_threads",
    "write_tum",
]
