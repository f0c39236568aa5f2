"""The import graph flows one way: each part of `agent/` and `drivers/` imports only parts of a
lower layer (and itself). Every import counts, inside functions and under TYPE_CHECKING too,
so a cycle cannot hide in a function body. A failure names the file and the import."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# Lowest first. `drivers` depends on nothing above it; the value types every layer shares
# are drivers/values.py's. The onboard runtime, the offline analysis and the ground console
# are one layer: none imports another. The identification core sits below the link and the model
# store, which carry and keep its result document (agent/ident/document.py).
LAYERS = (
    ("drivers",),
    ("agent", "agent.channels", "agent.logs", "agent.outputs", "agent.splane", "agent.fbwa"),
    ("agent.clock", "agent.config"),
    ("agent.excitation",),
    ("agent.ident",),
    ("agent.link", "agent.recorder", "agent.models"),
    ("agent.sizing", "agent.tune"),
    ("agent.runtime", "agent.analysis", "agent.ground"),
    ("agent.sim",),
    ("agent.cli",),
    ("agent.__main__",),
)
LEVEL = {part: level for level, parts in enumerate(LAYERS) for part in parts}


def part_of(module: str) -> str | None:
    """The layer entry a module belongs to: `drivers`, `agent`, or `agent.<first name>`."""
    names = module.split(".")
    if names[0] == "drivers":
        return "drivers"
    if names[0] != "agent":
        return None
    return "agent" if len(names) == 1 else f"agent.{names[1]}"


def sources():
    for path in sorted([*ROOT.glob("agent/**/*.py"), *ROOT.glob("drivers/**/*.py")]):
        module = ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
        yield path, module


def imports(path: Path):
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            yield from ((a.name, node.lineno) for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            yield node.module, node.lineno


def test_every_part_has_a_layer():
    parts = {part_of(module) for _, module in sources()}
    assert parts <= set(LEVEL), sorted(parts - set(LEVEL))


def test_imports_go_to_lower_layers_only():
    wrong = []
    for path, module in sources():
        own = part_of(module)
        for target, line in imports(path):
            other = part_of(target)
            if other is None or other == own:
                continue
            if LEVEL[other] >= LEVEL[own]:
                wrong.append(
                    f"{path.relative_to(ROOT)}:{line} imports {target} "
                    f"({own} may not import {other})"
                )
    assert not wrong, "\n".join(wrong)


@pytest.mark.parametrize(
    ("module", "target", "allowed"),
    [
        ("drivers.sensor", "agent.config", False),
        ("agent.runtime", "agent.analysis.identify", False),
        ("agent.cli.sim", "agent.sim.flight", True),
        ("agent.ident.job", "agent.channels", True),
        # The result document is the identification core's; the link and the store carry it.
        ("agent.link.messages", "agent.ident.document", True),
        ("agent.models", "agent.ident.document", True),
        ("agent.ident.aircraft.model", "agent.models", False),
    ],
)
def test_the_rule_itself(module, target, allowed):
    # The check above on imports whose answer is known: three the layers forbid (a driver
    # reading the agent's config; the onboard runtime reaching into the offline analysis; the
    # identification core reaching up into the model store).
    assert (LEVEL[part_of(target)] < LEVEL[part_of(module)]) is allowed
