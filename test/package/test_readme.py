"""The README and the docs document what the package really has, and say each thing once."""

import math
from pathlib import Path
import re
import sys

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT / 'scripts'), str(ROOT / 'bench')]
README = ROOT / 'README.md'
MAX_README_LINES = 300
# A markdown link or picture to a file of the repository: [text](path) or [text](path#anchor).
LINK = re.compile(r'\]\(((?:\.\./)?[\w./-]+?)(?:#[\w-]+)?\)')


def arm_yaml() -> dict:
    """config/arm.yaml as `section.name` -> value, `/**` names bare, node names prefixed."""
    flat = {}

    def walk(tree, prefix):
        for key, value in tree.items():
            if isinstance(value, dict):
                walk(value, f'{prefix}{key}.')
            else:
                flat[f'{prefix}{key}'] = value
    for section, body in yaml.safe_load((ROOT / 'config' / 'arm.yaml').read_text()).items():
        walk(body['ros__parameters'], '' if section == '/**' else f'{section.strip("/")}.')
    return flat


def key_parameter_rows(text: str):
    """(names, defaults) of each row of the README's key-parameter table."""
    table = text.split('## Key parameters')[1].split('\n## ')[0]
    for row in table.splitlines():
        cells = [cell.strip() for cell in row.strip().strip('|').split('|')]
        if len(cells) == 3 and cells[0].startswith('`'):
            names = re.findall(r'`([\w.]+)`', cells[0])
            values = [yaml.safe_load(v) for v in re.findall(r'`([^`]+)`', cells[1])]
            yield names, values


def test_the_readme_is_short():
    assert len(README.read_text().splitlines()) <= MAX_README_LINES


def test_every_key_parameter_in_the_readme_is_the_parameter_files():
    parameters = arm_yaml()
    rows = list(key_parameter_rows(README.read_text()))
    assert len(rows) >= 10
    for names, values in rows:
        assert len(names) == len(values), names
        for name, value in zip(names, values):
            assert name in parameters, f'{name}: not in config/arm.yaml'
            assert parameters[name] == value, \
                f'{name}: README {value}, arm.yaml {parameters[name]}'


def test_a_parameter_named_with_a_number_in_any_page_has_that_value():
    # "`name` (1.5 V", "`name` (5°" or "`name` = 0.5": a number written beside a parameter's
    # name, in its own units or in degrees for an angle.
    parameters = arm_yaml()
    pages = [README, *sorted((ROOT / 'docs').glob('*.md'))]
    for page in pages:
        if page.name == 'parameters.md':
            continue                    # generated from the file itself
        for name, number, degrees in re.findall(
                r'`([\w.]+)` (?:\(|= ?)(-?\d+(?:\.\d+)?)(°?)', page.read_text()):
            value = math.radians(float(number)) if degrees else float(number)
            known = [v for key, v in parameters.items()
                     if (key == name or key.endswith('.' + name)) and isinstance(v, (int, float))]
            if known:
                assert any(math.isclose(value, v, rel_tol=2e-3) for v in known), (page.name, name)


@pytest.mark.parametrize('page', [README, *sorted((ROOT / 'docs').glob('*.md')),
                                  *sorted((ROOT / 'docs' / 'benchmarks').glob('*.md'))],
                         ids=lambda page: page.name)
def test_every_link_resolves(page):
    for target in LINK.findall(page.read_text()):
        if '://' in target or not re.search(r'\.\w+$', target):
            continue
        assert (page.parent / target).resolve().exists(), f'{page.name}: {target}'


def test_the_readme_links_every_docs_page():
    readme = README.read_text()
    reachable = set(re.findall(r'docs/([\w.-]+\.md)', readme))
    for page in (ROOT / 'docs').glob('*.md'):
        assert page.name in reachable, f'docs/{page.name} is not linked from the README'


def test_every_executable_and_script_named_exists():
    readme = README.read_text()
    setup = (ROOT / 'setup.py').read_text()
    for executable in set(re.findall(r'ros2 run arm_control (\w+)', readme)):
        assert f"'{executable} = " in setup, executable
    for script in set(re.findall(r'(scripts/\w+(?:\.(?:sh|py))?)\b', readme)):
        assert (ROOT / script).is_file(), script


def test_the_launch_arguments_documented_are_the_launch_files():
    launch = (ROOT / 'launch' / 'arm.launch.py').read_text()
    declared = set(re.findall(r"DeclareLaunchArgument\(\s*'(\w+)'", launch))
    page = (ROOT / 'docs' / 'running.md').read_text()
    section = page.split('## The launch file')[1].split('\n## ')[0]
    assert declared <= set(re.findall(r'`(\w+)`', section)), declared
    for text in (README.read_text(), page):
        for line in text.splitlines():
            if 'arm.launch.py' in line:
                assert set(re.findall(r'(\w+):=', line)) <= declared, line


def test_the_parameter_page_is_generated_from_the_parameter_file():
    from parameter_table import page, PAGE
    assert PAGE.read_text() == page(), 'run: python scripts/parameter_table.py --write'


def test_the_benchmark_index_lists_every_benchmark_page():
    from docs_table import index
    assert (ROOT / 'docs' / 'benchmarks.md').read_text() == index(), \
        'run: python bench/docs_table.py'
