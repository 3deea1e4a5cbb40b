"""Print the README's parameter table from config/arm.yaml: names, defaults, descriptions.

    python scripts/parameter_table.py            # print it
    python scripts/parameter_table.py --write    # put it into README.md between its markers
"""

from pathlib import Path
import sys

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from arm_control.parameters import parameter_descriptions  # noqa: E402

BEGIN, END = '<!-- parameters:begin -->', '<!-- parameters:end -->'


def flatten(tree, prefix=''):
    for key, value in tree.items():
        if isinstance(value, dict):
            yield from flatten(value, f'{prefix}{key}.')
        else:
            yield f'{prefix}{key}', value


def table(path=ROOT / 'config' / 'arm.yaml') -> str:
    lines = []
    for section, body in yaml.safe_load(path.read_text()).items():
        descriptions = parameter_descriptions(path, section.strip('/'))
        who = 'every node' if section == '/**' else f'`{section.strip("/")}`'
        lines += ['', f'{who} (`{section}`):', '',
                  '| parameter | default | meaning |', '|---|---|---|']
        for name, value in flatten(body['ros__parameters']):
            shown = yaml.safe_dump(value, default_flow_style=True).strip().removesuffix('...')
            lines.append(f'| `{name}` | `{shown.strip()}` | {descriptions.get(name, "")} |')
    return '\n'.join(lines[1:])


def main():
    text = table()
    if '--write' not in sys.argv:
        print(text)
        return
    readme = ROOT / 'README.md'
    before, rest = readme.read_text().split(BEGIN)
    _, after = rest.split(END)
    readme.write_text(f'{before}{BEGIN}\n{text}\n{END}{after}')


if __name__ == '__main__':
    main()
