"""`edccif.agents` is a package of one module per role; the names the commands,
the tests and the docs use are importable from the package, each defined in
exactly one module, and the doctests of every module run."""

import doctest
import importlib
import pkgutil

import edccif.agents as agents

ROLES = ["agent", "cli", "common", "inbox", "orchestrate", "sensor", "startup", "swarm_file", "transport"]

PUBLIC = {
    "common": ["KINDS", "AgentError", "key"],
    "swarm_file": ["DEFAULTS", "write_swarm", "swarm_key", "load_swarm_dict", "load_swarm"],
    "transport": ["free_ports", "zenoh_config", "tcp_bytes"],
    "inbox": ["COUNTERS", "unusable", "_Inbox"],
    "agent": ["run_agent", "_fuse"],
    "sensor": ["node_columns", "sensor_measurements", "run_sensor"],
    "orchestrate": ["MAX_PROCESSES_PER_CORE", "run_swarm", "check_swarm_request", "gather", "format_summary",
                    "_clear_previous_run"],
    "cli": ["add_subcommands", "cmd_agent", "cmd_sensor", "cmd_swarm"],
}


def test_the_package_has_one_module_per_role():
    assert sorted(m.name for m in pkgutil.iter_modules(agents.__path__)) == ROLES


def test_every_name_is_reexported_from_the_module_that_defines_it():
    for role, names in PUBLIC.items():
        mod = importlib.import_module(f"edccif.agents.{role}")
        for name in names:
            assert getattr(agents, name) is getattr(mod, name), (role, name)
            obj = getattr(mod, name)
            if callable(obj) and hasattr(obj, "__module__"):
                assert obj.__module__ == f"edccif.agents.{role}", (role, name, obj.__module__)


def test_the_doctests_of_every_module_run():
    attempted = 0
    for role in ROLES:
        r = doctest.testmod(importlib.import_module(f"edccif.agents.{role}"))
        assert r.failed == 0, role
        attempted += r.attempted
    assert attempted >= 1, "the modules have doctests (key's at least)"


def test_the_command_line_takes_the_subcommands_from_the_package():
    from edccif.cli import build_parser

    p = build_parser()
    args = p.parse_args(["agent", "--swarm", "x.json", "--node", "0"])
    assert args.func is agents.cmd_agent
