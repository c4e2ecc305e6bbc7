"""The extension's export list (`#[pymodule] mod _edccif` in
`crates/edccif-py/src/lib.rs`) and its stub (`_edccif.pyi`) name the same things:
every public name the module has is typed in the stub, and every public name the
stub types exists at run time (`mypy.stubtest` checks signatures, but with
`--ignore-missing-stub` not a name the stub forgot)."""

import ast
from pathlib import Path

import edccif
from edccif import _edccif

STUB = Path(edccif.__file__).with_name("_edccif.pyi")


def stub_names() -> set:
    names = set()
    for node in ast.parse(STUB.read_text()).body:
        if isinstance(node, (ast.ClassDef, ast.FunctionDef)):
            names.add(node.name)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
        elif isinstance(node, ast.Assign):
            names.update(t.id for t in node.targets if isinstance(t, ast.Name))
    return {n for n in names if not n.startswith("_")}


def module_names() -> set:
    return {n for n in dir(_edccif) if not n.startswith("_")}


def test_every_export_is_in_the_stub():
    missing = module_names() - stub_names()
    assert not missing, f"exported by the extension but not typed in _edccif.pyi: {sorted(missing)}"


def test_every_stub_name_is_exported():
    missing = stub_names() - module_names()
    assert not missing, f"typed in _edccif.pyi but not exported by the extension: {sorted(missing)}"


def test_the_export_list_has_every_kind():
    """Classes, functions, exception types and the version, each reached through
    the export list or its initialiser (a group dropped from the list fails here)."""
    assert isinstance(_edccif.__version__, str) and _edccif.__version__
    for cls in ("Scenario", "Network", "ModelNetwork", "Node", "CKF", "ETCIF", "CustomMotion", "WirePacket"):
        assert isinstance(getattr(_edccif, cls), type), cls
    for fn in ("run", "monte_carlo", "ci_fuse", "replay", "encode_packet", "reliability_report"):
        assert callable(getattr(_edccif, fn)), fn
    errors = [n for n in module_names() if n.endswith("Error")]
    assert len(errors) >= 13, errors
    for n in errors:
        assert issubclass(getattr(_edccif, n), _edccif.EdccifError), n
    assert issubclass(_edccif.ArgumentTypeError, TypeError)
