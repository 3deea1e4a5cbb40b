"""What the launch file does before it starts a node: no launch and no rclpy imports here.

Parameter files come in layers: the arm's file, then a robot's overlay naming only what
differs. ROS applies several ``--params-file`` in order, the later winning, and
``node_parameters`` merges them the same way, so the set checked here is the set each node
gets. A namespace moves the nodes, but a file's node sections name nodes by their full
name (``/sim`` is not ``/arm1/sim``), so ``namespaced_parameter_files`` writes copies whose
sections follow the nodes.
"""

from pathlib import Path
import re

import yaml

from arm_control.config import ArmConfig, NODE_CONFIGS
from arm_control.parameters import default_parameter_file, ParameterError, read_parameter_file


def node_parameters(files, node_name: str) -> tuple[dict, dict]:
    """({name: value}, {name: the file that set it}) for ``node_name``: the installed
    defaults (what every node declares), then the files in order."""
    merged, sources = {}, {}
    for path in [default_parameter_file(), *files]:
        layer = read_parameter_file(path, node_name)
        merged.update(layer)
        sources.update(dict.fromkeys(layer, str(path)))
    return merged, sources


def check_parameter_files(files) -> ArmConfig:
    """The arm the files describe, once every node's settings are checked; else a
    ParameterError naming the parameter, its value and the file that set it."""
    arm = None
    for node_name, node_config in NODE_CONFIGS.items():
        params, sources = node_parameters(files, node_name)
        try:
            arm = ArmConfig.from_parameters(params)
            node_config.from_parameters(params)
        except ParameterError as error:
            named = re.search(r"parameter '([^']+)'", str(error))
            source = sources.get(named[1]) if named else None
            where = f'set in {source}' if source else f"in none of {', '.join(map(str, files))}"
            raise ParameterError(f'{error} ({where}, read for {node_name})') from error
    return arm


def namespaced_parameter_files(files, namespace: str, folder) -> list[Path]:
    """Copies of ``files`` in ``folder`` whose node sections (``/sim:``) name the node in
    ``namespace`` (``/arm1/sim:``); wildcard sections (``/**:``) stay as they are."""
    namespace = namespace.strip('/')
    out = []
    for index, path in enumerate(files):
        document = yaml.safe_load(Path(path).read_text(encoding='utf-8')) or {}
        moved = {}
        for key, body in document.items():
            node_name = key.strip('/')
            moved[key if '*' in key or '/' in node_name else f'/{namespace}/{node_name}'] = body
        copy = Path(folder) / f'{index}_{Path(path).name}'
        copy.write_text(yaml.safe_dump(moved, sort_keys=False), encoding='utf-8')
        out.append(copy)
    return out
