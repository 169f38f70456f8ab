"""The compiled core's cache: ``python -m app warm`` compiles on a cold cache and loads from a
warm one, and the image build warms it."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path


def warm(cache: Path) -> str:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    done = subprocess.run([sys.executable, "-m", "app", "warm"], env=env, capture_output=True,
                          text=True, timeout=600, check=True)
    return done.stdout + done.stderr


def test_warm_compiles_into_a_cold_cache_and_then_loads_from_it(tmp_path: Path) -> None:
    first = warm(tmp_path)
    assert "it compiles" in first and "kernels in" in first  # said before and after
    assert any(tmp_path.rglob("*.nbi"))
    second = warm(tmp_path)
    assert "loaded from its cache" in second, second


def test_the_image_build_warms_the_cache() -> None:
    dockerfile = (Path(__file__).parents[1] / "Dockerfile").read_text()
    install = dockerfile.index('pip install --no-cache-dir ".[service]"')
    assert install < dockerfile.index("python -m app warm") < dockerfile.index("USER shield")


def test_warm_leaves_nothing_to_compile_for_the_presets() -> None:
    """After :func:`warm`, steps of every preset (learning, asking only, failing, ending)
    and their snapshots call no kernel for types it was not compiled for."""
    from app.core import Shield, compiled

    compiled.warm()
    before = {id(k): len(k.signatures) for k in compiled.kernels()}
    for config in compiled.presets():
        Shield.from_snapshot(compiled._drive(Shield(config)).snapshot())
    grown = [k.py_func.__qualname__ for k in compiled.kernels()
             if len(k.signatures) != before[id(k)]]
    assert grown == []
