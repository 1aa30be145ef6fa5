"""Import a generator script (``repro/assets/<robot>/make_urdf.py``) from its file, for the
tests that check a committed URDF is the script's output byte for byte."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType


def import_script(script: Path, name: str) -> ModuleType:
    """The module of ``script`` under the name ``name`` (registered in ``sys.modules`` only
    while it executes: dataclasses look their module up there)."""
    spec = importlib.util.spec_from_file_location(name, script)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    try:
        spec.loader.exec_module(module)
    finally:
        del sys.modules[spec.name]
    return module
