"""The fuzz tests' workspace: one directory, emulated UR controller and session log for them all."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.fuzz.targets import TEST_HANG_S, Workspace


@pytest.fixture(scope="session")
def workspace(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Workspace]:
    ws = Workspace(tmp_path_factory.mktemp("fuzz"), hang_s=TEST_HANG_S)
    try:
        yield ws
    finally:
        ws.close()
