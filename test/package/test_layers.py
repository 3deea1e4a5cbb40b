"""The house keeps its layers: imports point down the floors ``scripts/draw_layers.py`` draws
(the picture and this test read one rule), rclpy stays in the node shells, no module reaches
back to one that imports it, and no test module imports another.

Read from the source (ast), so a new import is checked the moment it is written."""

import ast
from pathlib import Path
import re
import sys

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / 'arm_control'
sys.path.insert(0, str(ROOT / 'scripts'))
import draw_layers  # noqa: E402, I100

ROS_CLIENT = 'rclpy'


def imports(path: Path) -> set[str]:
    """Every module ``path`` imports, at any depth of its code (a lazy import counts)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.add(node.module)
            found |= {f'{node.module}.{alias.name}' for alias in node.names}
    return found


def module_name(path: Path) -> str:
    return '.'.join(path.relative_to(ROOT).with_suffix('').parts).removesuffix('.__init__')


SOURCES = {module_name(path): path for path in sorted(PACKAGE.rglob('*.py'))}


def test_every_room_has_a_floor():
    rooms = {draw_layers.room_of(module) for module in SOURCES if module != PACKAGE.name}
    assert rooms <= set(draw_layers.LAYERS), sorted(rooms - set(draw_layers.LAYERS))


def test_the_shells_are_the_executables():
    scripts = re.findall(r"'[\w]+ = arm_control\.nodes\.(\w+):", (ROOT / 'setup.py').read_text())
    assert set(scripts) == draw_layers.SHELLS


def test_imports_point_down_the_floors():
    _, _, edges = draw_layers.read_imports(PACKAGE)
    wrong = sorted(f'{a} -> {b}' for a, b in edges if draw_layers.wrong_way(a, b))
    assert edges and not wrong, wrong


def test_rclpy_stays_in_the_node_shells():
    users = sorted(module for module, path in SOURCES.items()
                   if any(name.split('.')[0] == ROS_CLIENT for name in imports(path)))
    assert users and all(draw_layers.room_of(module) == 'nodes' for module in users), users


PROCESS_MODULES = {'multiprocessing', 'subprocess', 'signal'}


def test_plans_are_pure_of_processes():
    """What times and plans (``plans/``) is called the same in-process and in the worker:
    pipes, child processes and signals are the worker shell's (``nodes/plan_worker.py``)."""
    users = sorted(module for module, path in SOURCES.items()
                   if draw_layers.room_of(module) == 'plans'
                   and {name.split('.')[0] for name in imports(path)} & PROCESS_MODULES)
    assert any(draw_layers.room_of(module) == 'plans' for module in SOURCES) and not users, \
        users


def test_no_module_reaches_back_to_one_that_imports_it():
    graph = {module: {name for name in imports(path) if name in SOURCES} - {module}
             for module, path in SOURCES.items()}
    visiting, done = [], set()

    def visit(module):
        if module in visiting:
            pytest.fail('import circle: ' + ' -> '.join(
                visiting[visiting.index(module):] + [module]))
        if module not in done:
            visiting.append(module)
            for name in sorted(graph[module]):
                visit(name)
            visiting.pop()
            done.add(module)

    for module in sorted(graph):
        visit(module)


def test_no_test_module_imports_another():
    """Nor does a bench: what tests and benches share lives in the rigs."""
    tests = {path.stem for path in (ROOT / 'test').rglob('test_*.py')}
    sources = sorted((ROOT / 'test').rglob('*.py')) + sorted((ROOT / 'bench').glob('*.py'))
    borrowing = {path.name: sorted({name.split('.')[0] for name in imports(path)}
                                   & tests - {path.stem})
                 for path in sources}
    assert not {name: borrowed for name, borrowed in borrowing.items() if borrowed}


MAX_MODULE_LINES, MAX_CLASS_LINES = 400, 300


def test_no_module_or_class_is_too_long():
    """No module over MAX_MODULE_LINES lines, no class over MAX_CLASS_LINES (its decorators
    and docstring included): a newcomer reads each in one sitting."""
    long = []
    for module, path in SOURCES.items():
        text = path.read_text()
        if len(text.splitlines()) > MAX_MODULE_LINES:
            long.append(f'{module}: {len(text.splitlines())} lines')
        for node in ast.walk(ast.parse(text, str(path))):
            if isinstance(node, ast.ClassDef):
                first = min([node.lineno] + [d.lineno for d in node.decorator_list])
                if node.end_lineno - first + 1 > MAX_CLASS_LINES:
                    long.append(f'{module}.{node.name}: {node.end_lineno - first + 1} lines')
    assert not long, long
