"""The earlier runs every fault test starts from (built once per test process)."""

import pytest

from tooling.faults import make_base


@pytest.fixture(scope="session")
def base(tmp_path_factory):
    return make_base(tmp_path_factory.mktemp("base"))
