"""Kernel signatures stay short: every ``@wp.kernel``/``@wp.func`` and ``@ti.kernel``/``@ti.func`` of kernels/ takes at
most MAX_ARGUMENTS arguments; a processor's fixed tables travel grouped (``wp.struct`` / ``ti.types.argpack``,
tile_processor.md §8). Oracle: the source's syntax tree (nothing is imported)."""

import ast
from pathlib import Path

KERNELS = Path(__file__).resolve().parents[2] / "kernels"
MAX_ARGUMENTS = 12


def test_no_kernel_or_function_takes_more_than_twelve_arguments():
    long = []
    for path in sorted(KERNELS.glob("*.py")):
        for node in ast.parse(path.read_text()).body:
            if not isinstance(node, ast.FunctionDef):
                continue
            decorators = [ast.unparse(d) for d in node.decorator_list]
            if any(d.startswith(("wp.", "ti.")) for d in decorators) and len(node.args.args) > MAX_ARGUMENTS:
                long.append(f"{path.name}:{node.lineno} {node.name} ({len(node.args.args)})")
    assert not long, f"more than {MAX_ARGUMENTS} arguments: {long}"
