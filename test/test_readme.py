"""The README documents what the package really has."""

from pathlib import Path
import re
import sys

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'scripts'))


def test_parameter_table_matches_the_parameter_file():
    from parameter_table import BEGIN, END, table
    readme = (ROOT / 'README.md').read_text()
    documented = readme.split(BEGIN)[1].split(END)[0].strip()
    assert documented == table().strip(), 'run: python scripts/parameter_table.py --write'


def test_every_executable_and_script_named_exists():
    readme = (ROOT / 'README.md').read_text()
    setup = (ROOT / 'setup.py').read_text()
    for executable in set(re.findall(r'ros2 run arm_control (\w+)', readme)):
        assert f"'{executable} = " in setup, executable
    for script in set(re.findall(r'(scripts/\w+\.(?:sh|py))', readme)):
        assert (ROOT / script).is_file(), script
    for picture in re.findall(r'\]\((docs/[\w.]+)\)', readme):
        assert (ROOT / picture).is_file(), picture
