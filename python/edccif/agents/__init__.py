"""Live agents: every estimator node and every sensor its own process, talking over Zenoh.

A *swarm file* (JSON, written by :func:`write_swarm` or ``edccif swarm``) says
everything the processes share: the scenario, the algorithm row and its options,
the swarm id, the step period, the deadlines, the loopback (or real) endpoints and
the faults to inject. Then

- ``edccif agent --swarm FILE --node I`` runs estimator node ``I``
  (:func:`run_agent`): at each step it waits for its sensor's measurement (up to
  ``sensor_wait_s`` after the step's start), runs its local phase, publishes its
  packet and waits for its neighbours' packets of each fusion phase (up to
  ``deadline_s`` per phase), then fuses what arrived (weights renormalised over
  it). Packets that arrive after their phase are dropped and counted as late;
  packets without a valid authentication tag (HMAC-SHA256 under the swarm file's
  key), whose header names another swarm or a sender that is not a neighbour,
  that cannot be used (wrong dimension, indefinite matrix), or whose step is far
  from the agent's (replayed, or too far ahead) are rejected and counted; the
  agent goes on.
- ``edccif sensor --swarm FILE --node I`` runs sensor ``I`` (:func:`run_sensor`):
  at each step's start it takes its measurement (simulated from the scenario and
  seed, or replayed from an MCAP or TUM file) and runs its event trigger; only
  triggered measurements are published.
- ``edccif swarm --nodes N`` (:func:`run_swarm`) writes a swarm file with free
  loopback ports, starts ``N`` agents and ``N`` sensors, starts them together,
  injects the faults asked for (kill and restart an agent), waits, gathers every
  agent's estimates and prints the position RMSE, the trigger rate and the bytes
  sent per link type — measured on the agents' and sensors' TCP sockets — beside
  the in-process accounting of ``run``.

Key expressions (one per swarm, node and kind)::

    edccif/<swarm>/<node>/measurement    sensor <node> -> its agent
    edccif/<swarm>/<node>/contribution   agent <node> -> neighbours (diffusion adaptation)
    edccif/<swarm>/<node>/information    agent <node> -> neighbours (CI combination, consensus rounds)
    edccif/<swarm>/<node>/estimate       agent <node> -> neighbours (convex combination)
    edccif/<swarm>/<node>/alive          liveliness token of agent <node>

Payloads are signed packets of the wire format (``edccif.encode_packet(...,
key=)``, docs/formats.md); the tag, then the header's swarm, sender, step and
round are checked against the key expression, the receiver's swarm and its step.
See docs/agents.md (and its threat model).

This module needs the ``agents`` extra (``pip install 'edccif[agents]'``, the
``eclipse-zenoh`` wheel); it is imported only by the commands above.
"""

from __future__ import annotations

from .agent import (  # noqa: F401
    _fuse,
    run_agent,
)
from .cli import (  # noqa: F401
    add_subcommands,
    cmd_agent,
    cmd_sensor,
    cmd_swarm,
)
from .common import (  # noqa: F401
    KINDS,
    AgentError,
    key,
)
from .inbox import (  # noqa: F401
    COUNTERS,
    _Inbox,
    unusable,
)
from .orchestrate import (  # noqa: F401
    MAX_PROCESSES_PER_CORE,
    _clear_previous_run,
    check_swarm_request,
    format_summary,
    gather,
    run_swarm,
)
from .sensor import (  # noqa: F401
    node_columns,
    run_sensor,
    sensor_measurements,
)
from .swarm_file import (  # noqa: F401
    DEFAULTS,
    load_swarm,
    load_swarm_dict,
    swarm_key,
    write_swarm,
)
from .transport import (  # noqa: F401
    free_ports,
    tcp_bytes,
    zenoh_config,
)
