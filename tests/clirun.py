"""The in-process command line for tests: ``run(*args)`` invokes ``clfx`` through click's
`CliRunner` and checks its exit code."""
from click.testing import CliRunner

from clfx.cli import cli


def run(*args, code=0, input=None):
    """``clfx ARGS`` in this process (``input``: its stdin); asserts the exit code is ``code``
    (the output and stderr in the message) and returns click's `Result`.  Exceptions
    propagate."""
    result = CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False,
                                input=input)
    assert result.exit_code == code, (result.exit_code, result.output, result.stderr)
    return result
