"""The compiled core's cache: ``python -m app warm`` compiles on a cold cache and loads from a
warm one, the image build warms it, and an edit to any source of the core reaches every kernel
that calls it."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).parents[1]


def warm(cache: Path) -> str:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    done = subprocess.run(
        [sys.executable, "-m", "app", "warm"],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=True,
    )
    return done.stdout + done.stderr


def test_warm_compiles_into_a_cold_cache_and_then_loads_from_it(tmp_path: Path) -> None:
    first = warm(tmp_path)
    assert "it compiles" in first and "kernels in" in first  # said before and after
    assert any(tmp_path.rglob("*.nbi"))
    second = warm(tmp_path)
    assert "loaded from its cache" in second, second


def test_the_image_build_warms_a_cache_that_the_service_user_may_write() -> None:
    """numba refuses a cache folder it cannot write (then, with no home to fall back on, it
    cannot even import the core): the image warms its own folder and hands it to the user the
    service runs as."""
    dockerfile = (Path(__file__).parents[1] / "Dockerfile").read_text()
    install = dockerfile.index('pip install --no-cache-dir ".[service]"')
    assert "NUMBA_CACHE_DIR=/srv/numba-cache" in dockerfile[:install]
    assert (
        install
        < dockerfile.index("python -m app warm")
        < dockerfile.index('chown -R shield "$NUMBA_CACHE_DIR"')
        < dockerfile.index("USER shield")
    )


def test_warm_leaves_nothing_to_compile_for_the_presets() -> None:
    """After :func:`warm`, steps of every preset (learning, asking only, failing, ending)
    and their snapshots call no kernel for types it was not compiled for."""
    from app.core import Shield, compiled

    compiled.warm()
    before = {id(k): len(k.signatures) for k in compiled.kernels()}
    for config in compiled.presets():
        Shield.from_snapshot(compiled._drive(Shield(config)).snapshot())
    grown = [
        k.py_func.__qualname__ for k in compiled.kernels() if len(k.signatures) != before[id(k)]
    ]
    assert grown == []


LIMIT = (
    "from app.core import Shield, compiled; "
    "shield = compiled._drive(Shield(compiled.presets()[0])); "
    "print(shield.step([10.0, 30.0, 10.0], 0.0).threshold)"
)


def test_an_edited_callee_reaches_its_cached_caller(tmp_path: Path) -> None:
    """A copy of the package, its cache warm; then only ``risk.py`` changes (the limit of
    the total risk of every action, made huge). ``step.learn_and_decide``, whose module did not
    change, must run the new ``risk.total_risk``: numba alone would load it from the cache
    with the old one inside."""
    shutil.copytree(ROOT / "app", tmp_path / "app", ignore=shutil.ignore_patterns("__pycache__"))
    env = {**os.environ, "PYTHONPATH": str(tmp_path), "NUMBA_CACHE_DIR": str(tmp_path / "cache")}

    def limit() -> float:
        done = subprocess.run(
            [sys.executable, "-c", LIMIT],
            cwd=tmp_path,
            env=env,
            capture_output=True,
            text=True,
            timeout=600,
            check=True,
        )
        return float(done.stdout.split()[-1])

    assert limit() <= 1.0
    risk = tmp_path / "app" / "core" / "risk.py"
    source = risk.read_text()
    assert "total[a] = 1.0 - spared" in source
    risk.write_text(source.replace("total[a] = 1.0 - spared", "total[a] = 1e300"))
    assert limit() == 1e300


def test_a_stale_fingerprint_clears_the_cores_kernels_and_nothing_else(tmp_path: Path) -> None:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    where = (
        "from app.core import compiled; print(*compiled.cache_folders(), compiled.fingerprint())"
    )

    def start() -> list[str]:
        return subprocess.run(
            [sys.executable, "-c", where],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
            timeout=120,
            check=True,
        ).stdout.split()

    folder, fingerprint = start()
    stamp = Path(folder) / "core-sources.sha256"
    assert stamp.read_text() == fingerprint  # a new cache is stamped
    core = Path(folder) / "reach.risk-1.py311.nbi"
    other = Path(folder) / "elsewhere.f-1.py311.nbi"
    for path in (core, other):
        path.write_bytes(b"")
    assert start() == [folder, fingerprint] and core.exists()  # current: kept
    stamp.write_text("an older core")
    start()
    assert not core.exists() and other.exists() and stamp.read_text() == fingerprint


def test_with_no_folder_numba_can_cache_in_the_core_loads_and_caches_in_a_temporary_one(
    tmp_path: Path,
) -> None:
    """numba asked to look only where the user points it (``NUMBA_CACHE_DIR``, unset here)
    finds no folder, as a read-only install run by a user without a home does: the core
    still loads, caching in the temporary folder, and says so."""
    env = {key: value for key, value in os.environ.items() if key != "NUMBA_CACHE_DIR"}
    env |= {"NUMBA_CACHE_LOCATOR_CLASSES": "UserProvidedCacheLocator", "TMPDIR": str(tmp_path)}
    code = (
        "import numpy as np; from app.core import risk; "
        "t = np.empty(1); risk.total_risk(np.array([[0.5, 0.5]]), t); print(t[0])"
    )
    done = subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
    )
    assert done.stdout.split() == ["0.75"]
    assert "no folder it can write" in done.stderr
    assert any((tmp_path / f"efsm-numba-{os.getuid()}").rglob("risk.total_risk-*.nbi"))


def test_the_temporary_cache_folder_is_one_only_its_user_may_write(tmp_path: Path) -> None:
    from app.core._cache_folder import private_folder

    mine = private_folder(tmp_path / "efsm-numba-x")
    assert mine == tmp_path / "efsm-numba-x" and private_folder(mine) == mine
    shared = tmp_path / "efsm-numba-y"
    shared.mkdir()
    shared.chmod(0o777)  # anyone may write it: another folder, made for us alone
    other = private_folder(shared)
    assert other != shared and other.parent == tmp_path
    assert other.stat().st_mode & 0o777 == 0o700
