import signal

import pytest

import edccif


@pytest.fixture(scope="session", autouse=True)
def python_handles_ctrl_c():
    """Tests press Ctrl-C (``_thread.interrupt_main``, SIGINT to children) and
    expect ``KeyboardInterrupt``, what a user at a terminal gets. A shell
    without job control starts background commands with SIGINT ignored, and
    Python then leaves it ignored: ``interrupt_main`` does nothing and the
    children inherit the ignore. For the session, SIGINT gets Python's own
    handler (children start with the default disposition, as from a terminal)."""
    before = signal.getsignal(signal.SIGINT)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, before)


@pytest.fixture(scope="session")
def sc4():
    return edccif.Scenario.paper(nodes=4)


@pytest.fixture(scope="session")
def sim4(sc4):
    return sc4.simulate(seed=3)
