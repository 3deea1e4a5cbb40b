"""The house keeps its layers: each package imports only those beneath it, rclpy stays in the
node shells, no module reaches back to one that imports it, and no test imports another.

Read from the source (ast), so a new import is checked the moment it is written."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / 'arm_control'

# What each part may import, beside the standard library and third-party libraries. The
# physics (model) and the parameters are the floor; the node shells and the launch helpers
# are the roof; nothing below the roof imports rclpy.
MAY_IMPORT = {
    'parameters': set(),
    'config': {'parameters'},
    'model': {'config', 'parameters'},
    'planning': {'config', 'parameters', 'model'},
    'control': {'config', 'parameters', 'model', 'text'},
    'sysid': {'config', 'parameters', 'model', 'logs'},
    'logs': {'config', 'parameters', 'model'},
    'visual': {'config', 'parameters', 'model', 'logs', 'text'},
    'realtime': set(),
    'text': set(),
    'frc': {'config', 'parameters', 'model', 'realtime'},
    'nodes': {'config', 'parameters', 'model', 'planning', 'control', 'sysid', 'logs',
              'visual', 'realtime', 'text', 'frc'},
    'bringup': {'config', 'parameters'},
}
ROS_CLIENT = 'rclpy'


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix('').parts
    return '.'.join(parts[:-1] if parts[-1] == '__init__' else parts)


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


SOURCES = {module_name(path): path for path in sorted(PACKAGE.rglob('*.py'))}


def part(module: str) -> str:
    """'arm_control.control.plans' -> 'control'; 'arm_control.config' -> 'config'."""
    return module.split('.')[1]


def own_imports(module: str) -> set[str]:
    """The package's modules that ``module`` imports (a name imported from a package that is
    a module of its own counts as that module)."""
    return {name for name in imports(SOURCES[module]) if name in SOURCES} - {module}


def test_every_part_is_placed_in_the_layers():
    parts = {part(module) for module in SOURCES if module != 'arm_control'}
    assert parts <= set(MAY_IMPORT), sorted(parts - set(MAY_IMPORT))


@pytest.mark.parametrize('module', [m for m in SOURCES if m != 'arm_control'])
def test_a_module_imports_only_the_layers_beneath_it(module):
    allowed = MAY_IMPORT[part(module)] | {part(module)}
    reaching_up = sorted(name for name in own_imports(module)
                         if name != 'arm_control' and part(name) not in allowed)
    assert not reaching_up, f'{module} imports {reaching_up}'


def test_rclpy_stays_in_the_node_shells():
    users = sorted(module for module, path in SOURCES.items()
                   if any(name.split('.')[0] == ROS_CLIENT for name in imports(path)))
    assert users and all(part(module) == 'nodes' for module in users), users


def test_no_module_reaches_back_to_one_that_imports_it():
    graph = {module: own_imports(module) for module in SOURCES}
    visiting, done = [], set()

    def visit(module):
        if module in visiting:
            pytest.fail('import circle: ' + ' -> '.join(
                visiting[visiting.index(module):] + [module]))
        if module in done:
            return
        visiting.append(module)
        for name in sorted(graph[module]):
            visit(name)
        visiting.pop()
        done.add(module)

    for module in sorted(graph):
        visit(module)


def test_no_test_module_imports_another():
    tests = {path.stem for path in (ROOT / 'test').rglob('test_*.py')}
    for path in sorted((ROOT / 'test').rglob('*.py')):
        borrowed = sorted(name.split('.')[0] for name in imports(path)
                          if name.split('.')[0] in tests - {path.stem})
        assert not borrowed, f'{path.name} imports {borrowed}'
