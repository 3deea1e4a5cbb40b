"""Draw the package's layers and the imports between them, from the code as it is.

Each room is a folder of ``arm_control/`` (or a module at its top), on the floor its layer
gives it: the parameter files, the arm description and the logs at the bottom, the model
with the world, timing, planning, identification and the FRC side on it, plans (a goal's
path checked and timed, for whoever needs a trajectory) above them, control (which follows
timed motions) and what people see above that, and the node shells on top. An
arrow is the imports from one room to another (their count); one that runs up a floor, or
sideways between two node shells, is drawn red and listed under the picture.

    python scripts/draw_layers.py docs/layers.png                 # this checkout
    python scripts/draw_layers.py docs/layers_before.png --repo /path/to/an/older/checkout
"""

import argparse
import ast
from collections import Counter, defaultdict
from pathlib import Path
import sys

import matplotlib
matplotlib.use('Agg')
from matplotlib import patches, pyplot  # noqa: E402

# Floor of each room (higher imports lower), and what it holds, for the picture.
LAYERS = {'parameters': 0, 'text': 0, 'realtime': 0, 'config': 1, 'logs': 1, 'model': 2,
          'timing': 3, 'planning': 3, 'sysid': 3, 'frc': 3, 'plans': 4, 'control': 5,
          'visual': 5, 'bringup': 6, 'nodes': 6}
# Modules of nodes/ that are executables (setup.py's console scripts): a shell importing
# another shell is sideways.
SHELLS = {'sim', 'controller_start', 'planner', 'tour', 'viewer', 'markers', 'recorder',
          'frc_bridge', 'sysid', 'arm_cli'}
# What draws does not run the loop or plan.
RUNS_THE_LOOP = ('control.controller', 'control.arm_controller', 'control.closed_loop',
                 'planning.planner')


def room_of(module: str) -> str:
    return module.split('.')[1] if module.count('.') >= 1 else module


def read_imports(package: Path):
    """(lines per room, files per room, [(from module, to module)]) of ``package``."""
    lines, files, edges = Counter(), defaultdict(list), []
    for path in sorted(package.rglob('*.py')):
        relative = path.relative_to(package.parent).with_suffix('')
        module = '.'.join(relative.parts).removesuffix('.__init__')
        if module == package.name:
            continue
        text = path.read_text()
        room = room_of(module)
        lines[room] += len(text.splitlines())
        files[room].append(path.stem)
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.ImportFrom) and node.module and \
                    node.module.startswith(package.name + '.'):
                targets = [node.module] + [f'{node.module}.{a.name}' for a in node.names]
                target = max((t for t in targets if (package.parent / (
                    t.replace('.', '/') + '.py')).exists()), key=len, default=node.module)
                edges.append((module, target))
            elif isinstance(node, ast.Import):
                edges += [(module, a.name) for a in node.names
                          if a.name.startswith(package.name + '.')]
    return lines, files, edges


def wrong_way(source: str, target: str) -> bool:
    """Up a floor, sideways between two rooms of one floor or two node shells, or the
    drawing code running the loop."""
    a, b = room_of(source), room_of(target)
    if a == b == 'nodes':
        return target.split('.')[-1] in SHELLS
    if a == 'visual' and target.split('.', 1)[-1].startswith(RUNS_THE_LOOP):
        return True
    return a != b and LAYERS.get(a, 9) <= LAYERS.get(b, 9)


def draw(package: Path, output: Path, title: str) -> list[str]:
    lines, files, edges = read_imports(package)
    rooms = sorted(lines, key=lambda r: (LAYERS.get(r, 9), r))
    floors = defaultdict(list)
    for room in rooms:
        floors[LAYERS.get(room, 9)].append(room)
    position = {}
    for floor, members in floors.items():
        for k, room in enumerate(members):
            position[room] = ((k + 0.5) / len(members), 0.08 + 0.14 * floor)
    figure = pyplot.figure(figsize=(11, 9), dpi=100)
    ax = figure.add_axes([0.02, 0.16, 0.96, 0.78])
    ax.set_xlim(-0.05, 1.05)
    ax.set_ylim(0.0, 0.98)
    ax.axis('off')
    counts = Counter((room_of(a), room_of(b)) for a, b in edges if room_of(a) != room_of(b))
    bad = sorted({f'{a} -> {b}' for a, b in edges if wrong_way(a, b)})
    bad_rooms = {(room_of(a), room_of(b)) for a, b in edges if wrong_way(a, b)}
    for (a, b), count in counts.items():
        (xa, ya), (xb, yb) = position[a], position[b]
        red = (a, b) in bad_rooms
        ax.annotate('', xy=(xb, yb + 0.045), xytext=(xa, ya - 0.045),
                    arrowprops=dict(arrowstyle='->', lw=1.0 + 0.15 * min(count, 20),
                                    color='#c0392b' if red else '#7f8c8d',
                                    connectionstyle='arc3,rad=0.12'))
        ax.text((xa + xb) / 2, (ya + yb) / 2, str(count), fontsize=8,
                color='#c0392b' if red else '#555')
    for room, (x, y) in position.items():
        width = min(0.9 / len(floors[LAYERS.get(room, 9)]), 0.3)
        sideways = any(a == b == room for a, b in bad_rooms)
        ax.add_patch(patches.FancyBboxPatch(
            (x - width / 2, y - 0.045), width, 0.09, boxstyle='round,pad=0.005',
            facecolor='#dfe8f1', edgecolor='#c0392b' if sideways else '#34495e'))
        name = f'{room}/' if len(files[room]) > 1 or room in ('model', 'control', 'planning',
                                                              'timing', 'visual', 'nodes') else \
            f'{room}.py'
        ax.text(x, y + 0.018, f'{name}  {lines[room]} lines', ha='center', fontsize=10,
                weight='bold')
        modules = sorted(m for m in files[room] if m != '__init__')
        listed = ', '.join(modules) if len(modules) > 1 else ''
        if len(listed) > 60:
            listed = listed[:57].rsplit(', ', 1)[0] + ', ...'
        ax.text(x, y - 0.012, listed, ha='center', fontsize=7, color='#333')
        biggest = max((p.stat().st_size, p.name) for p in (package / room).glob('*.py')) \
            if (package / room).is_dir() else None
        if biggest:
            count = len((package / room / biggest[1]).read_text().splitlines())
            ax.text(x, y - 0.034, f'largest: {biggest[1]} ({count})', ha='center', fontsize=7,
                    color='#c0392b' if count > 400 else '#666')
    ax.set_title(f'{title}: layers and imports (arrows point from importer to imported)',
                 fontsize=12)
    listed = '\n'.join(bad[:12]) + (f'\n... and {len(bad) - 12} more' if len(bad) > 12 else '')
    text = ('Imports that run the wrong way (up a floor; sideways, as between two node shells'
            ' or control and planning; drawing code running the loop):\n'
            + (listed if bad else 'none'))
    figure.text(0.03, 0.02, text, fontsize=8, family='monospace', va='bottom',
                color='#c0392b' if bad else '#2c7a3a')
    output.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(output)
    pyplot.close(figure)
    return bad


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('output', type=Path, help='the PNG to write')
    parser.add_argument('--repo', type=Path, default=Path(__file__).resolve().parents[1],
                        help='the checkout to draw (default: this one)')
    parser.add_argument('--title', default='arm_control')
    args = parser.parse_args(argv)
    bad = draw(args.repo / 'arm_control', args.output, args.title)
    print(f'wrote {args.output}; {len(bad)} imports run the wrong way')
    for line in bad:
        print(f'  {line}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
