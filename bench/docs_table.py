"""Write a benchmark's table into docs/benchmarks/<name>.md, headed by its date and commit.

Every bench prints its table and, with ``--write-docs``, keeps it here: the README and the
docs link these pages and never copy their numbers.
"""

import datetime
import pathlib
import subprocess

DOCS = pathlib.Path(__file__).resolve().parent.parent / 'docs' / 'benchmarks'


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
    return path
