"""How a capture waits for each pose to be set: Enter at a prompt, or a trigger command that sets it."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

from fitgen.physics.pose import POSE_NAMES, off_skin

from host.capture import Schedule
from host.prompt import ask_line

TRIGGER_TIMEOUT = 60.0  # s a trigger may take to set a pose (--trigger-timeout): a hung one must not hang the capture


class TriggerFailed(RuntimeError):
    """The trigger command did not succeed."""


def enter_waiter(schedule: Schedule, stdin=None, stderr=None):
    """Wait for Enter on ``stdin``; 'q' or the end of input stops."""
    stdin = stdin or sys.stdin
    stderr = stderr or sys.stderr
    total = len(schedule.poses)

    def wait(i: int, pose) -> bool:
        rest = " (the indenter lifted off the skin: the sensor at rest)" if off_skin(schedule.poses[i:i + 1])[0] else ""
        prompt = f"pose {i + 1}/{total}: {schedule.describe(i)}{rest}; set it, then press Enter (q to stop) "
        return ask_line(stdin, stderr, prompt) is not None

    return wait


def trigger_waiter(command: str, schedule: Schedule, timeout: float = TRIGGER_TIMEOUT):
    """Run ``command`` (a shell command line) for each pose; it must exit 0 once the pose is set, within
    ``timeout`` seconds (else it is killed, with whatever it started, and TriggerFailed says so).

    Its environment has TM_POSE_INDEX (1-based), TM_POSE_COUNT and TM_DX, TM_DY, TM_DZ, TM_THX, TM_THY.
    """
    total = len(schedule.poses)

    def wait(i: int, pose) -> bool:
        env = dict(os.environ, TM_POSE_INDEX=str(i + 1), TM_POSE_COUNT=str(total),
                   **{f"TM_{n.upper()}": repr(float(v)) for n, v in zip(POSE_NAMES, pose)})
        try:  # a process group of its own: on expiry the shell and every command it started are killed
            proc = subprocess.Popen(command, shell=True, env=env, start_new_session=True)
        except OSError as exc:
            raise TriggerFailed(f"trigger {command!r} could not run: {exc.strerror}") from None
        try:
            code = proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            _kill_group(proc)
            raise TriggerFailed(f"trigger {command!r} did not exit within {timeout:g} s (--trigger-timeout) "
                                f"at pose {i + 1}/{total} ({schedule.describe(i)})") from None
        except BaseException:  # Ctrl-C: it no longer gets the terminal's SIGINT in its own group
            _kill_group(proc)
            raise
        if code != 0:
            raise TriggerFailed(f"trigger {command!r} failed with exit status {code} "
                                f"at pose {i + 1}/{total} ({schedule.describe(i)})")
        return True

    return wait


def _kill_group(proc: subprocess.Popen) -> None:
    """SIGKILL to ``proc``'s process group (it leads one), then reap it."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    # waitpid, not proc.wait(): a Ctrl-C just after Popen.wait's non-blocking acquire of its internal lock leaves
    # the lock held, and a second wait() blocks on it for ever (one CI run hung so)
    try:
        proc.returncode = os.waitstatus_to_exitcode(os.waitpid(proc.pid, 0)[1])
    except ChildProcessError:  # reaped already, by the interrupted wait: its status is lost, and no caller reads it
        proc.returncode = 0 if proc.returncode is None else proc.returncode
