"""The ``agent``, ``sensor`` and ``swarm`` subcommands of the ``edccif`` command."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any, Dict

from .. import _edccif
from .agent import run_agent
from .orchestrate import _check_swarm_size, check_swarm_request, format_summary, run_swarm
from .sensor import run_sensor
from .swarm_file import DEFAULTS


def cmd_agent(args: argparse.Namespace) -> int:
    s = run_agent(args.swarm, args.node, rejoin=args.rejoin)
    print(json.dumps({k: s[k] for k in ("node", "first_step", "steps", "inbox")}))
    return 0


def cmd_sensor(args: argparse.Namespace) -> int:
    s = run_sensor(args.swarm, args.node)
    print(json.dumps({k: s[k] for k in ("node", "measured", "triggered")}))
    return 0


def cmd_swarm(args: argparse.Namespace) -> int:
    from .. import _args

    _args.check_output_file(args.json, args.force, "json")
    if args.scenario:
        sc = _edccif.Scenario.from_toml(args.scenario)
    else:
        _check_swarm_size(args.nodes)  # before building a scenario of that size
        sc = _edccif.Scenario.paper(nodes=args.nodes)
    if args.steps is not None:
        sc = sc.replace(steps=args.steps)
    check_swarm_request(sc, loss=args.loss, delay=args.delay, kill=args.kill)
    settings: Dict[str, Any] = {"period_s": args.period, "deadline_s": args.deadline}
    if args.sensor_wait is not None:
        settings["sensor_wait_s"] = args.sensor_wait
    res = run_swarm(sc.nodes, args.algorithm, scenario=sc, seed=args.seed, out=args.out,
                    loss=args.loss, loss_seed=args.seed, delay=args.delay, kill=args.kill, force=args.force,
                    progress=not args.quiet, **settings)
    # the summary file first: printing may meet a closed pipe
    if args.json:
        Path(args.json).write_text(json.dumps(res["summary"], indent=1))
    print(format_summary(res["summary"]))
    return 0


def add_subcommands(sub: Any) -> None:
    """Adds ``agent``, ``sensor`` and ``swarm`` to the ``edccif`` command."""
    from .. import _args

    a = sub.add_parser("agent", help="run one estimator node of a swarm as this process (Zenoh)")
    a.add_argument("--swarm", required=True, help="swarm file (JSON, see docs/agents.md)")
    a.add_argument("--node", type=_args.node_index, required=True, help="node index")
    a.add_argument("--rejoin", action="store_true", help="join a running swarm from a neighbour's estimate")
    a.set_defaults(func=cmd_agent)
    s = sub.add_parser("sensor", help="run one sensor of a swarm as this process: triggered measurements only")
    s.add_argument("--swarm", required=True, help="swarm file (JSON); its 'source' says simulate, mcap or tum")
    s.add_argument("--node", type=_args.node_index, required=True, help="node index of the sensor")
    s.set_defaults(func=cmd_sensor)
    w = sub.add_parser("swarm", help="run N agents and N sensors as processes over Zenoh on loopback")
    w.add_argument("--nodes", type=_args.count, default=4, help="nodes of the built-in scenario (default 4)")
    w.add_argument("--scenario", help="a scenario TOML file instead of the built-in one")
    w.add_argument("--algorithm", default="edc-cif", type=_args.algorithm,
                   help="the row to run, any case (default edc-cif)")
    w.add_argument("--seed", type=_args.seed, default=0)
    w.add_argument("--steps", type=_args.count, help="steps (default: the scenario's)")
    w.add_argument("--period", type=_args.positive, default=DEFAULTS["period_s"],
                   help="step period in s (default 0.05)")
    w.add_argument("--sensor-wait", type=_args.positive, help="how long a step waits for its sensor (s)")
    w.add_argument("--deadline", type=_args.positive, default=DEFAULTS["deadline_s"],
                   help="how long a fusion phase waits for the neighbours (s, default 1)")
    w.add_argument("--loss", type=_args.real(0.0, 1.0, hi_open=True, meaning="a probability"), default=0.0,
                   help="fraction of packets dropped at every sender, in [0, 1)")
    w.add_argument("--delay", type=_args.delay, action="append", default=[], metavar="FROM:TO:SECONDS",
                   help="delay agent FROM's packets to agent TO (repeatable)")
    w.add_argument("--kill", type=_args.kill, metavar="NODE@STEP[+DOWN_S]",
                   help="kill agent NODE at STEP, restart it DOWN_S later (default 1 s)")
    w.add_argument("--out", type=_args.output_dir, default="swarm",
                   help="directory for the swarm file, logs and outputs (default swarm); an earlier run there "
                   "needs --force")
    w.add_argument("--json", type=_args.output_path, help="also write the summary to this JSON file")
    w.add_argument("--force", action="store_true",
                   help="replace an earlier swarm run in --out (only the files a run writes) and --json")
    w.add_argument("--quiet", action="store_true", help="no progress lines")
    w.set_defaults(func=cmd_swarm)
