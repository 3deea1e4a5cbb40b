"""Busy loops: processes that each keep one core busy, at normal priority, for a while.

The load of issue 12 ("two busy processes loading both cores"): each is a plain Python
``pass`` loop that checks the clock, so it stops by itself after ``seconds`` even if whoever
started it dies first.

    python bench/busy.py                     # two loops for 60 s
    python bench/busy.py --count 2 --seconds 300
"""

import argparse
import signal
import subprocess
import sys

LOOP = 'import time\nend = time.monotonic() + {seconds}\nwhile time.monotonic() < end:\n    pass\n'


def start(count: int = 2, seconds: float = 600.0) -> list:
    """``count`` busy-loop processes, each ending by itself after ``seconds``."""
    return [subprocess.Popen([sys.executable, '-c', LOOP.format(seconds=float(seconds))])
            for _ in range(count)]


def stop(processes) -> None:
    """End the loops started by ``start`` (they would end by themselves anyway)."""
    for process in processes:
        if process.poll() is None:
            process.terminate()
    for process in processes:
        process.wait()


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--count', type=int, default=2, help='busy processes')
    parser.add_argument('--seconds', type=float, default=60.0, help='how long they run (s)')
    args = parser.parse_args()
    # Killed (SIGTERM), end the loops too: Python's default would leave them running.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    loops = start(args.count, args.seconds)
    try:
        for process in loops:
            process.wait()
    finally:
        stop(loops)


if __name__ == '__main__':
    main()
