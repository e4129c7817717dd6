"""Shared plumbing for the headless entry points in blender_scripts/.

Each script runs both as `blender -b -P blender_scripts/X.py -- ARGS` (Debian's Blender 3.4)
and as `python blender_scripts/X.py ARGS` (the bpy 5.0 module).  No bpy import here.
"""
import argparse
import sys
import traceback


from .contract import UserError  # noqa: F401  (the one UserError of both worlds, re-exported for the scripts)


def script_argv(argv=None):
    """The script's own arguments: after '--' under the Blender binary, else argv[1:]."""
    argv = list(sys.argv if argv is None else argv)
    if "--" in argv:
        return argv[argv.index("--") + 1:]
    return argv[1:]


def run_main(main, prog):
    """Call main(argv); turn UserError into one stderr line + exit 2, crashes into exit 1.

    The Blender binary returns 0 after an uncaught exception in a -P script, so every
    failure must end in an explicit exit code.
    """
    # The scripts' own argparse parsers: a usage error becomes one stderr line like every other
    # bad input (the usage text stays in --help).  restored when main returns.
    saved_error, argparse.ArgumentParser.error = argparse.ArgumentParser.error, _one_line_usage_error
    try:
        code = main(script_argv())
    except UserError as e:
        sys.stderr.write(f"{prog}: error: {e}\n")
        sys.stderr.flush()
        _exit(2)
    except SystemExit as e:  # argparse --help / usage errors
        _exit(e.code if isinstance(e.code, int) else (0 if e.code is None else 2))
    except KeyboardInterrupt:
        sys.stderr.write(f"{prog}: interrupted\n")
        _exit(130)
    except Exception:
        traceback.print_exc()
        _exit(1)
    finally:
        argparse.ArgumentParser.error = saved_error
    _exit(code or 0)


def _one_line_usage_error(parser, message):
    parser.exit(2, f"{parser.prog}: error: {message} (see --help)\n")


def _exit(code):
    sys.stdout.flush()
    sys.stderr.flush()
    # os._exit would skip Blender's cleanup of temp files; sys.exit is honoured by both the
    # Blender binary (-P) and plain Python.
    sys.exit(code)
