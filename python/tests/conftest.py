import pytest

import edccif


@pytest.fixture(scope="session")
def sc4():
    return edccif.Scenario.paper(nodes=4)


@pytest.fixture(scope="session")
def sim4(sc4):
    return sc4.simulate(seed=3)
