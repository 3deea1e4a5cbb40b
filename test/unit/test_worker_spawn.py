"""The plan worker runs the controller's own arm_control, wherever the controller was started
from: from a directory that holds another copy of the package (a checkout's root, say) the
worker had imported that one, and died on the messages its node sent it."""

import arm_control
from arm_control.nodes.worker_spawn import PACKAGE_ROOT, spawn


def test_the_worker_imports_this_process_s_package_not_the_working_directory_s(
        tmp_path, monkeypatch):
    other = tmp_path / 'arm_control'
    other.mkdir()
    (other / '__init__.py').write_text('raise SystemExit(7)\n')
    monkeypatch.chdir(tmp_path)
    worker = spawn()
    try:
        worker.stdin.close()                # no request: the worker ends at once, with 0
        assert worker.wait(60) == 0
    finally:
        if worker.poll() is None:
            worker.kill()
            worker.wait()
    assert arm_control.__file__.startswith(PACKAGE_ROOT)
