"""The one package logger (``logging.getLogger("meshphase")``), the one style of the
messages the ``meshphase`` command prints on stderr, and whether stderr is a terminal (where
progress bars are drawn).

Every message line, whatever prints it (the command's errors and run status, a stage's
warning collected in a run, a Python warning, a log record), reads::

    meshphase COMMAND: LEVEL: [WHERE: ]TEXT

``LEVEL`` is ``error``, ``warning``, ``info``, ``debug``, ``partial``, ``unreliable``,
``interrupted`` or (a campaign's recording) ``failed``; ``WHERE`` is the stage (``phasing``), the warning class
(``FormatWarning``) or the library that logged it (``distributed.scheduler``).
"""

from __future__ import annotations

import logging
import sys

logger = logging.getLogger("meshphase")
logger.addHandler(logging.NullHandler())

__all__ = ["logger", "message_line", "MessageFormatter", "stderr_is_terminal"]


def stderr_is_terminal() -> bool:
    """True when stderr is a terminal: progress bars are drawn only there (a log file, a pipe
    or a cluster job's output would get a line per redraw)."""
    try:
        return bool(sys.stderr.isatty())
    except (AttributeError, ValueError):   # replaced by an object without it, or closed
        return False


def message_line(command: str, level: str, text) -> str:
    """One message line of the command: ``meshphase COMMAND: LEVEL: TEXT`` on one line.

    Parameters
    ----------
    command : str
        The subcommand (``"process"``); "" for none (``meshphase: LEVEL: TEXT``).
    level : str
        ``"error"``, ``"warning"``, ``"partial"``, ... (lower case by convention).
    text : object
        The message; newlines and runs of blanks become one blank; empty: the line ends
        after LEVEL (``meshphase process: interrupted``).

    Returns
    -------
    str
    """
    if not isinstance(command, str) or not isinstance(level, str):
        raise TypeError(f"command and level must be strings, got {type(command).__name__} and "
                        f"{type(level).__name__}")
    if not level.strip():
        raise ValueError("level must not be empty (e.g. 'warning')")
    prog = f"meshphase {command}" if command.strip() else "meshphase"
    text = " ".join(str(text).split())
    return f"{prog}: {level.strip()}" + (f": {text}" if text else "")


class MessageFormatter(logging.Formatter):
    """Log records as :func:`message_line` lines: the level in lower case, records of other
    libraries' loggers prefixed with the logger's name, a ``COMMAND: `` at the start of our
    own message dropped (the line names the command already); a traceback (``--debug``)
    follows on its own lines.

    Parameters
    ----------
    command : str
        The subcommand the lines are for.
    """

    def __init__(self, command: str):
        if not isinstance(command, str):
            raise TypeError(f"command must be a string, got {type(command).__name__}")
        super().__init__()
        self.command = command

    def format(self, record: logging.LogRecord) -> str:
        text = record.getMessage()
        if record.name == "meshphase" or record.name.startswith("meshphase."):
            if self.command and text.startswith(f"{self.command}: "):
                text = text[len(self.command) + 2:]
        else:
            text = f"{record.name}: {text}"
        line = message_line(self.command, record.levelname.lower(), text)
        if record.exc_info:
            line += "\n" + self.formatException(record.exc_info)
        elif record.exc_text:
            line += "\n" + record.exc_text
        return line
