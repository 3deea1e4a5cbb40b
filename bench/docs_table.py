"""Write a benchmark's table into docs/benchmarks/<name>.md, headed by its date and commit.

Every bench prints its table and, with ``--write-docs``, keeps it here: the README and the
docs link these pages and never copy their numbers. docs/benchmarks.md, their index, is
rewritten with every page (``python bench/docs_table.py`` rewrites it alone).
"""

import datetime
import pathlib
import subprocess

DOCS = pathlib.Path(__file__).resolve().parent.parent / 'docs' / 'benchmarks'
INDEX_HEAD = '''# Benchmarks

Each page holds the table a bench printed, headed by the date and commit it ran at, and the
command that reproduces it (`scripts/bench.sh` runs them all). The numbers come from a shared
2-core machine: compare rows of one table, not tables of different days. What the figures say
about the arm's weak spots is in [known_limits.md](known_limits.md).

'''


def commit() -> str:
    """The checkout's commit, with '+dirty' when the work tree differs from it."""
    here = DOCS.parent.parent

    def git(*args):
        return subprocess.run(['git', *args], cwd=here, capture_output=True, text=True)
    head = git('rev-parse', '--short', 'HEAD').stdout.strip() or 'unknown'
    dirty = git('status', '--porcelain', '--untracked-files=no').stdout.strip()
    return head + ('+dirty' if dirty else '')


def write(name: str, title: str, command: str, table: str) -> pathlib.Path:
    """Keep ``table`` (markdown) as docs/benchmarks/<name>.md with its date, commit and command."""
    DOCS.mkdir(parents=True, exist_ok=True)
    path = DOCS / f'{name}.md'
    date = datetime.datetime.now(datetime.timezone.utc).strftime('%Y-%m-%d %H:%M UTC')
    path.write_text(f'# {title}\n\n{date}, commit {commit()}: `{command}`\n\n{table.rstrip()}\n')
    write_index()
    return path


def index() -> str:
    """docs/benchmarks.md: a link to every page, by its title."""
    rows = []
    for page in sorted(DOCS.glob('*.md')):
        title = page.read_text().split('\n', 1)[0].lstrip('# ').strip()
        rows.append(f'- [{title}](benchmarks/{page.name})')
    return INDEX_HEAD + '\n'.join(rows) + '\n'


def write_index() -> pathlib.Path:
    path = DOCS.parent / 'benchmarks.md'
    path.write_text(index())
    return path


if __name__ == '__main__':
    write_index()
