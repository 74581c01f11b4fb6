"""What a render's stats record about where it came from: the tracer's version, the git commit
of its checkout, the command line and the date. Cheap, and never raises."""
import datetime
import functools
import os
import subprocess
import sys

__version__ = "0.1.0"  # the one place the version lives (pyproject.toml repeats it)


@functools.lru_cache(maxsize=1)
def git_commit():
    """HEAD of the git checkout that holds the tracer package, with "-dirty" when `git status`
    shows changes to tracked files; None without git, outside a checkout, or when the package is
    not tracked there (e.g. installed into a virtual environment inside some other repository).

    Looked up once per process: the code that runs is the code imported when it started."""
    folder = os.path.dirname(os.path.abspath(__file__))
    env = dict(os.environ, GIT_OPTIONAL_LOCKS="0")  # `git status` must not take the index lock

    def git(*args):
        return subprocess.run(["git", "-C", folder, *args], capture_output=True, text=True, timeout=5,
                              check=True, env=env, stdin=subprocess.DEVNULL).stdout.strip()

    try:
        git("ls-files", "--error-unmatch", "--", "__init__.py")
        head = git("rev-parse", "HEAD")
        dirty = git("status", "--porcelain", "--untracked-files=no")
    except (OSError, ValueError, subprocess.SubprocessError):
        return None
    return head + ("-dirty" if dirty else "") if head else None


def provenance():
    """{tracer_version, git_commit (or None), command_line (sys.argv), date (ISO 8601, local time
    with its UTC offset)} for a render's stats."""
    return {
        "tracer_version": __version__,
        "git_commit": git_commit(),
        "command_line": list(sys.argv),
        "date": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
    }
