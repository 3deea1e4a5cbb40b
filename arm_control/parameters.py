"""ROS parameter files, read the way a node sees them: flat, layered, described, typed.

A parameter file maps node sections (``/**`` for every node, ``/<node>`` for one) to
``ros__parameters``; nested keys are dotted names. Several files layer as several
``--params-file`` do: a later file overrides an earlier one, name by name, so a robot file
can name only what differs from ``config/arm.yaml``, the one source of every default.
"""

import math
from pathlib import Path
import re
from typing import Any, Mapping

import yaml

PACKAGE = 'arm_control'


class ParameterError(ValueError):
    """A parameter is missing, of the wrong type or out of range, or its file is unreadable."""


def default_parameter_file(name: str = 'arm.yaml') -> Path:
    """The installed ``share/arm_control/config/<name>``, else the source tree's copy."""
    try:
        from ament_index_python.packages import get_package_share_directory
        installed = Path(get_package_share_directory(PACKAGE)) / 'config' / name
        if installed.is_file():
            return installed
    except (ImportError, LookupError, OSError, ValueError):
        pass
    return Path(__file__).resolve().parents[1] / 'config' / name


def _document(path):
    """The parsed file (libyaml's parser where there is one: ten times faster at start-up)."""
    loader = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)
    try:
        return yaml.load(Path(path).read_text(encoding='utf-8'), Loader=loader)
    except (OSError, yaml.YAMLError) as error:
        raise ParameterError(f'cannot read parameter file {path}: {error}') from error


def read_parameter_file(path, node_name: str) -> dict[str, Any]:
    """Flatten one ROS parameter file into ``{dotted.name: value}`` as ``node_name`` sees it.

    The ``/**`` section applies to every node; ``/<node_name>`` (or ``<node_name>``)
    overrides it.
    """
    document = _document(path)
    if not isinstance(document, dict):
        raise ParameterError(f'parameter file {path} is not a mapping of node sections')
    flat: dict[str, Any] = {}
    for section in ('/**', node_name, '/' + node_name):
        body = document.get(section)
        if body is None:
            continue
        if not isinstance(body, dict) or not isinstance(body.get('ros__parameters'), dict):
            raise ParameterError(f"section '{section}' of {path} has no ros__parameters mapping")
        _flatten(body['ros__parameters'], '', flat)
    return flat


def read_parameter_files(paths, node_name: str) -> dict[str, Any]:
    """The defaults of ``config/arm.yaml`` with each file of ``paths`` layered over them in
    order, as ``--params-file`` after ``--params-file`` does."""
    flat = read_parameter_file(default_parameter_file(), node_name)
    for path in paths:
        flat.update(read_parameter_file(path, node_name))
    return flat


def package_parameter_names(path) -> set[str]:
    """Every parameter name any section of ``path`` gives (all the package's nodes)."""
    document = _document(path)
    names: dict[str, Any] = {}
    for body in document.values():
        _flatten(body['ros__parameters'], '', names)
    return set(names)


def parameter_descriptions(path, node_name: str) -> dict[str, str]:
    """Each of ``node_name``'s parameters' description: the comment on its line of the file,
    else its section's; the node's own section's over ``/**``'s (names repeat across nodes).

    The comments in ``config/arm.yaml`` are the one place a parameter is described.
    """
    by_section: dict[str, dict[str, str]] = {}
    stack: list[tuple[int, str, str]] = []      # (indent, key, comment) of open sections
    for line in Path(path).read_text(encoding='utf-8').splitlines():
        match = re.match(r'^(\s*)([\w/*]+):\s*([^#]*?)\s*(?:#\s*(.*))?$', line)
        if not match:
            continue
        indent, key, value, comment = len(match[1]), match[2], match[3], match[4] or ''
        while stack and stack[-1][0] >= indent:
            stack.pop()
        if value and stack:
            names = [k for _, k, _ in stack[1:] if k != 'ros__parameters']
            inherited = next((c for _, _, c in reversed(stack) if c), '')
            section = by_section.setdefault(stack[0][1].strip('/'), {})
            section['.'.join(names + [key])] = comment or inherited
        elif not value:
            stack.append((indent, key, comment))
    return {**by_section.get('**', {}), **by_section.get(node_name, {})}


def _flatten(tree: dict, prefix: str, out: dict) -> None:
    for key, value in tree.items():
        name = f'{prefix}{key}'
        if isinstance(value, dict):
            _flatten(value, name + '.', out)
        else:
            out[name] = value


class Reader:
    """Typed, range-checked access to a flat parameter mapping; every failure names the
    parameter and its value."""

    def __init__(self, params: Mapping[str, Any]):
        self.params = params

    def _raw(self, name):
        if name not in self.params or self.params[name] is None:
            raise ParameterError(f"parameter '{name}' is missing")
        return self.params[name]

    def number(self, name, *, low=-math.inf, high=math.inf, low_open=False) -> float:
        value = self._raw(name)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParameterError(f"parameter '{name}' = {value!r}: expected a number")
        value = float(value)
        too_low = value <= low if low_open else value < low
        if not math.isfinite(value) or too_low or value > high:
            bound = f"{'>' if low_open else '>='} {low}" if too_low else f'<= {high}'
            if not math.isfinite(value):
                bound = 'finite'
            raise ParameterError(f"parameter '{name}' = {value!r}: must be {bound}")
        return value

    def positive(self, name) -> float:
        return self.number(name, low=0.0, low_open=True)

    def nonnegative(self, name) -> float:
        return self.number(name, low=0.0)

    def integer(self, name, *, low=-(2 ** 63), high=2 ** 63 - 1) -> int:
        value = self._raw(name)
        if isinstance(value, bool) or not isinstance(value, int):
            raise ParameterError(f"parameter '{name}' = {value!r}: expected an integer")
        if not low <= value <= high:
            raise ParameterError(f"parameter '{name}' = {value!r}: must be in [{low}, {high}]")
        return value

    def boolean(self, name) -> bool:
        value = self._raw(name)
        if not isinstance(value, bool):
            raise ParameterError(f"parameter '{name}' = {value!r}: expected true or false")
        return value

    def text(self, name) -> str:
        value = self._raw(name)
        if not isinstance(value, str) or not value:
            raise ParameterError(f"parameter '{name}' = {value!r}: expected a name")
        return value

    def numbers(self, name, length: int) -> tuple[float, ...]:
        value = self._raw(name)
        if (isinstance(value, (str, bytes)) or not hasattr(value, '__len__')
                or len(value) != length):
            raise ParameterError(f"parameter '{name}' = {value!r}: expected {length} numbers")
        out = []
        for item in value:
            if isinstance(item, bool) or not isinstance(item, (int, float)) \
                    or not math.isfinite(item):
                raise ParameterError(f"parameter '{name}' = {value!r}: expected finite numbers")
            out.append(float(item))
        return tuple(out)

    def positive_numbers(self, name, length: int) -> tuple[float, ...]:
        values = self.numbers(name, length)
        if min(values) <= 0.0:
            raise ParameterError(f"parameter '{name}' = {list(values)}: must be > 0")
        return values

    def strings(self, name) -> tuple[str, ...]:
        value = self._raw(name)
        if isinstance(value, str) or not all(isinstance(item, str) for item in value):
            raise ParameterError(f"parameter '{name}' = {value!r}: expected a list of names")
        return tuple(item for item in value if item)
