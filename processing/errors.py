"""The one deliberate input error of the tasks, below every module that raises it.

:class:`TaskError` is re-exported by processing.tasks (the runner's contract); processing.spacecraft and
others raise it without importing the task contract itself.
"""

from __future__ import annotations

__all__ = ["TaskError"]


class TaskError(ValueError):
    """The inputs or parameters do not allow the computation; the message says what and why.

    The one deliberate input error: the runner records its message as the job's failure reason."""
