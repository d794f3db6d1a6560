"""Where the tests find the source tree and the command-line program they compare against."""
import os
import pathlib
import shutil

import pytest

import isotouch

ROOT = pathlib.Path(os.environ.get("ISOTOUCH_SOURCE_DIR", pathlib.Path(__file__).resolve().parents[2]))


@pytest.fixture(scope="session")
def root():
    return ROOT


@pytest.fixture(scope="session")
def cli():
    """The `isotouch` program of the same build (ctest sets ISOTOUCH_BIN)."""
    path = os.environ.get("ISOTOUCH_BIN") or shutil.which("isotouch")
    assert path, "ISOTOUCH_BIN is not set and no isotouch on PATH"
    return path


@pytest.fixture(scope="session")
def head_path():
    return str(ROOT / "data/ct-head-headsq/headsq_64x64x93_int16.mhd")


# Subprocesses (the tour, Ctrl-C, the benchmark, the installed tree's check) import the same
# package as this process, from any working directory.
os.environ["PYTHONPATH"] = os.path.dirname(os.path.dirname(os.path.abspath(isotouch.__file__)))
