"""Lint like ROS (ament_flake8's rules: 99 columns, Google import order, single quotes)."""

from pathlib import Path
import subprocess
import sys

ROOT = Path(__file__).resolve().parents[2]


def test_flake8_finds_nothing():
    result = subprocess.run(
        [sys.executable, '-m', 'flake8', 'arm_control', 'test', 'bench', 'scripts', 'launch',
         'setup.py'], cwd=ROOT, capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr
