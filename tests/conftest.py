"""Shared fixtures of the test suite."""
import importlib.util
from pathlib import Path

import pytest


def _load_script(path: Path):
    """Import the script at ``path`` (an example or a results/ study, not a package module) as a
    fresh module named after its file."""
    path = Path(path)
    spec = importlib.util.spec_from_file_location(f"script_{path.stem}", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="session")
def load_script():
    """``load_script(path)``: a script outside the packages, imported as a module."""
    return _load_script
