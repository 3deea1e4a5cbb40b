"""Every library the package imports is declared in package.xml under its rosdep key.

``rosdep install --from-paths src --ignore-src -y`` installs what package.xml declares, and
nothing else: an import missing there works here and dies at start on a ROS user's machine.
The imports are read from the source (ast), so a new one is checked the moment it is written.
"""

import ast
from pathlib import Path
import sys
from xml.etree import ElementTree

ROOT = Path(__file__).resolve().parents[2]
RUN_TIME = ('arm_control', 'launch')          # exec_depend
TEST_TIME = ('test', 'bench', 'scripts')      # test_depend (or exec_depend)

# Top-level module -> rosdep key. ROS packages are keyed by their own name; Python libraries
# by their key in rosdistro's rosdep/python.yaml: the system package where there is one
# (python3-numpy), else the pip key (python3-toppra-pip).
MODULE_KEYS = {
    'rclpy': 'rclpy',
    'ament_index_python': 'ament_index_python',
    'launch': 'launch',
    'launch_ros': 'launch_ros',
    'builtin_interfaces': 'builtin_interfaces',
    'rcl_interfaces': 'rcl_interfaces',
    'rosgraph_msgs': 'rosgraph_msgs',
    'std_msgs': 'std_msgs',
    'std_srvs': 'std_srvs',
    'sensor_msgs': 'sensor_msgs',
    'geometry_msgs': 'geometry_msgs',
    'nav_msgs': 'nav_msgs',
    'trajectory_msgs': 'trajectory_msgs',
    'control_msgs': 'control_msgs',
    'action_msgs': 'action_msgs',
    'diagnostic_msgs': 'diagnostic_msgs',
    'visualization_msgs': 'visualization_msgs',
    'numpy': 'python3-numpy',
    'scipy': 'python3-scipy',
    'numba': 'python3-numba',
    'yaml': 'python3-yaml',
    'matplotlib': 'python3-matplotlib',
    'tkinter': 'python3-tk',                  # in the standard library, but Debian splits it
    'filterpy': 'python3-filterpy-pip',
    'toppra': 'python3-toppra-pip',
    'mcap': 'mcap-ros2-support',              # pip's mcap-ros2-support brings mcap with it
    'mcap_ros2': 'mcap-ros2-support',
    'rosbags': 'python3-rosbags-pip',
    'casadi': 'casadi-pip',
    'catkin_pkg': 'python3-catkin-pkg-modules',
    'pytest': 'python3-pytest',
    'pytest_timeout': 'python3-pytest-timeout',
    'hypothesis': 'python3-hypothesis',
    'flake8': 'python3-flake8',
    'flake8_import_order': 'python3-flake8-import-order',
    'flake8_quotes': 'python3-flake8-quotes',
}
# Libraries rosdistro has no key for (an invented key breaks `rosdep install` for everyone):
# module -> pip package, which README.md's ROS section must tell users to install.
PIP_ONLY = {
    'wpimath': 'robotpy-wpimath',
    'wpiutil': 'robotpy-wpiutil',
    'ntcore': 'pyntcore',
}
# Modules used with no import statement: (module, file, the text there that uses it).
USED_BY_NAME = (
    ('flake8', 'test/package/test_flake8.py', "'-m', 'flake8'"),
    ('flake8_import_order', 'setup.cfg', 'import-order-style'),
    ('flake8_quotes', 'setup.cfg', 'inline-quotes'),
    ('pytest_timeout', 'scripts/test.sh', '--timeout'),
    ('tkinter', 'arm_control/nodes/viewer.py', "'TkAgg'"),
)


def declared_keys(package_xml: Path) -> dict[str, set[str]]:
    """{'exec': keys, 'test': keys} from package.xml (<depend> counts as both)."""
    root = ElementTree.parse(package_xml).getroot()

    def keys(*tags):
        return {element.text.strip() for tag in tags for element in root.iter(tag)}
    return {'exec': keys('depend', 'exec_depend'), 'test': keys('depend', 'test_depend')}


def imported_modules(root: Path, folders) -> dict[str, list[str]]:
    """{top-level module: [files importing it]} for the third-party imports under ``folders``:
    neither the standard library (tkinter aside) nor this repository's own modules."""
    files = [path for folder in folders for path in sorted((root / folder).rglob('*.py'))]
    local = {'arm_control'} | {path.stem for folder in TEST_TIME + RUN_TIME
                               for path in (root / folder).rglob('*.py')}
    found: dict[str, list[str]] = {}
    for path in files:
        for node in ast.walk(ast.parse(path.read_text(encoding='utf-8'), str(path))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [node.module]
            else:
                continue
            for name in names:
                top = name.split('.')[0]
                if top in local or (top in sys.stdlib_module_names and top not in MODULE_KEYS):
                    continue
                found.setdefault(top, []).append(str(path.relative_to(root)))
    return found


def undeclared(root: Path, folders, declared: set[str], readme: str) -> list[str]:
    """A line for each imported module whose rosdep key is unknown or not declared."""
    problems = []
    for module, files in sorted(imported_modules(root, folders).items()):
        where = ', '.join(sorted(set(files)))
        if module in PIP_ONLY:
            if PIP_ONLY[module] not in readme:
                problems.append(f'{module} ({where}): rosdistro has no key for it; README.md '
                                f'must say to pip install {PIP_ONLY[module]}')
        elif module not in MODULE_KEYS:
            problems.append(f'{module} ({where}): no rosdep key known; add it to MODULE_KEYS '
                            'here (its key in rosdistro) and to package.xml')
        elif MODULE_KEYS[module] not in declared:
            problems.append(f'{module} ({where}): package.xml does not declare '
                            f'{MODULE_KEYS[module]}')
    return problems


def test_every_run_time_import_is_an_exec_depend():
    keys = declared_keys(ROOT / 'package.xml')
    problems = undeclared(ROOT, RUN_TIME, keys['exec'], (ROOT / 'README.md').read_text())
    assert not problems, '\n'.join(problems)


def test_every_test_and_bench_import_is_declared():
    keys = declared_keys(ROOT / 'package.xml')
    problems = undeclared(ROOT, TEST_TIME, keys['exec'] | keys['test'],
                          (ROOT / 'README.md').read_text())
    assert not problems, '\n'.join(problems)


def test_tools_run_by_name_are_declared():
    keys = declared_keys(ROOT / 'package.xml')
    for module, file_name, usage in USED_BY_NAME:
        assert usage in (ROOT / file_name).read_text(), \
            f'{file_name} no longer has {usage!r}: drop {module} from USED_BY_NAME'
        kind = 'exec' if file_name.split('/')[0] in RUN_TIME else 'test'
        wanted = keys['exec'] if kind == 'exec' else keys['exec'] | keys['test']
        assert MODULE_KEYS[module] in wanted, \
            f'{file_name} uses {module}: package.xml needs <{kind}_depend>{MODULE_KEYS[module]}'


def test_an_undeclared_import_is_named(tmp_path):
    """The check itself: a new library, imported anywhere in a module, fails it by name."""
    (tmp_path / 'arm_control').mkdir()
    (tmp_path / 'arm_control' / 'fit.py').write_text(
        'import os\nimport numpy as np\nfrom arm_control import config\n\n\n'
        'def fit():\n    from sklearn.linear_model import Ridge\n    import wpimath\n')
    problems = undeclared(tmp_path, ['arm_control'], {'python3-numpy'}, readme='')
    assert len(problems) == 2
    assert problems[0].startswith('sklearn (arm_control/fit.py): no rosdep key known')
    assert problems[1].startswith('wpimath (arm_control/fit.py): rosdistro has no key')
    problems = undeclared(tmp_path, ['arm_control'], set(), readme='pip install robotpy-wpimath')
    assert [p.split(' ')[0] for p in problems] == ['numpy', 'sklearn']


def test_the_readme_gives_the_one_install_command():
    readme = (ROOT / 'README.md').read_text()
    assert 'rosdep install --from-paths src --ignore-src -y' in readme
