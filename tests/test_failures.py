"""Failure kinds (planner.core.failures): the planners branch on a typed kind, not on text."""

import ast
from pathlib import Path

import planner
from planner.core.failures import FailureKind, Problem, kind_of, kinds_of_groups


def test_a_problem_reads_as_its_message_and_carries_its_kind():
    why = Problem("balance lost at sample 3 of the path", FailureKind.BALANCE)
    assert why == "balance lost at sample 3 of the path" and why
    assert f"swing of FL: {why}" == "swing of FL: balance lost at sample 3 of the path"
    assert kind_of(why) is FailureKind.BALANCE
    assert kind_of("") is None  # no failure
    assert kind_of("a message without a kind") is FailureKind.OTHER


def test_theta_groups_map_to_kinds_in_their_order():
    groups = ["balance_margin_landing", "contact", "torque", "an_unknown_group"]
    assert kinds_of_groups(groups) == (
        FailureKind.BALANCE_MARGIN,
        FailureKind.REACH,
        FailureKind.TORQUE,
        FailureKind.OTHER,
    )


_TEXT_NAMES = ("message", "why", "diagnosis", "reason", "msg")


def _branches_on_text(tree: ast.AST) -> list[int]:
    """Lines of ``"literal" in <a name or attribute that holds a message>``."""
    out = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Compare):
            continue
        for op, right in zip(node.ops, node.comparators, strict=True):
            if not isinstance(op, (ast.In, ast.NotIn)):
                continue
            name = right.attr if isinstance(right, ast.Attribute) else getattr(right, "id", "")
            if isinstance(node.left, ast.Constant) and isinstance(node.left.value, str):
                if any(t in name.lower() for t in _TEXT_NAMES):
                    out.append(node.lineno)
    return out


def test_no_planner_module_branches_on_failure_text():
    root = Path(planner.__file__).parent
    found = {}
    for path in root.rglob("*.py"):
        lines = _branches_on_text(ast.parse(path.read_text()))
        if lines:
            found[str(path.relative_to(root))] = lines
    assert found == {}


def test_the_text_scan_finds_a_constructed_branch():
    code = 'if "balance" in why or "interrupted" in plan.message:\n    pass\n'
    assert _branches_on_text(ast.parse(code)) == [1, 1]
