"""The core's numbers do not depend on the CPU (docs/algorithm.md, "Determinism").

Elementwise IEEE arithmetic (+, -, *, /, sqrt) rounds the same on every CPU; what does not is
arithmetic whose order or last bits a library picks for the machine: BLAS products (the kernel
follows the CPU), and numpy's SIMD loops for ``exp``, ``log`` and their kin (AVX-512 has its
own, and an array's alignment decides which elements take it). The core takes those through
``app.core._kernels`` instead; this test reads its sources so that no new use slips in. The
same suite also runs as another CPU would (``scripts/test``: numpy's dispatch off, numba's
generic target), which the recorded closed loop then checks end to end.
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from app.core import Shield, ShieldConfig

CORE = Path(__file__).parents[2] / "app" / "core"

# numpy functions whose results follow the CPU: transcendental SIMD loops and BLAS products
CPU_DEPENDENT = {
    "exp",
    "exp2",
    "expm1",
    "log",
    "log1p",
    "log2",
    "log10",
    "logaddexp",
    "logaddexp2",
    "power",
    "float_power",
    "sin",
    "cos",
    "tan",
    "arcsin",
    "arccos",
    "arctan",
    "arctan2",
    "sinh",
    "cosh",
    "tanh",
    "dot",
    "vdot",
    "inner",
    "matmul",
    "einsum",
    "tensordot",
    "linalg",
}


def cpu_dependent_uses(source: str) -> list[str]:
    """``np.<name>`` of :data:`CPU_DEPENDENT`, ``.dot(`` and ``@`` in a module's source."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if (
            isinstance(node, ast.Attribute)
            and isinstance(node.value, ast.Name)
            and node.value.id == "np"
            and node.attr in CPU_DEPENDENT
        ):
            found.append(f"line {node.lineno}: np.{node.attr}")
        elif isinstance(node, ast.Attribute) and node.attr == "dot":
            found.append(f"line {node.lineno}: .dot")
        elif isinstance(node, ast.BinOp | ast.AugAssign) and isinstance(node.op, ast.MatMult):
            found.append(f"line {node.lineno}: @")
    return found


def test_the_scan_finds_what_it_looks_for() -> None:
    source = "import numpy as np\nx = np.exp(a) + b @ c\ny = a.dot(b)\nz = np.linalg.solve(a, b)\n"
    assert sorted(cpu_dependent_uses(source)) == [
        "line 2: @",
        "line 2: np.exp",
        "line 3: .dot",
        "line 4: np.linalg",
    ]


@pytest.mark.parametrize("path", sorted(CORE.glob("*.py")), ids=lambda p: p.name)
def test_no_core_module_uses_arithmetic_whose_last_bits_follow_the_cpu(path: Path) -> None:
    assert cpu_dependent_uses(path.read_text()) == []


@pytest.mark.slow  # long streams: seconds
@pytest.mark.parametrize("config", [ShieldConfig(), ShieldConfig.paper()], ids=["risk", "paper"])
def test_a_restored_model_whose_arrays_lie_elsewhere_decides_as_the_original(
    config: ShieldConfig,
) -> None:
    """A snapshot round trip puts every array at a new address (and alignment); the restored
    model must decide, and go on learning, bit for bit as the original."""
    rng = np.random.default_rng(5)
    shield = Shield(config)

    def drive(model: Shield, steps: int, seed: int) -> list[tuple[float, bool]]:
        local = np.random.default_rng(seed)
        out = []
        for t in range(steps):
            obs = [local.uniform(5, 30), local.uniform(2, 120), local.uniform(5, 30)]
            if t % 40 == 39:
                event = "collision" if local.random() < 0.5 else "large_distance"
                model.step(obs, None, stream="s", event=event, done=True)
                continue
            decision = model.step(obs, float(local.uniform(-3, 2)), stream="s")
            assert decision.action is not None
            out.append((decision.action, decision.revised))
        return out

    drive(shield, 600, int(rng.integers(1 << 30)))
    snapshot = shield.snapshot()
    padding = [np.empty(int(n)) for n in rng.integers(1, 9, size=50)]  # move the allocator
    restored = Shield.from_snapshot(snapshot)
    del padding
    assert drive(restored, 400, 7) == drive(shield, 400, 7)
