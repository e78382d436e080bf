"""`python -m kinfu_cli` and the `kinfu` script.

The CLI is imported inside the handler (the one function-level import of the package, for this reason):
Ctrl-C during start-up imports then also ends with the one line `kinfu: interrupted`, exit 130.
"""

import gc
import os
import sys


def main() -> None:
    try:
        from kinfu_cli.cli import main as cli_main

        code = cli_main()
    except KeyboardInterrupt:
        sys.stderr.write("kinfu: interrupted\n")
        code = 130
    # The run is over: the shutdown's garbage collections would traverse every object numba and scipy made
    # (0.1-0.15 s of a 2 s `kinfu segment`) just before the process hands its memory back anyway. Freeze them
    # out of the collector; atexit handlers, thread joins and reference-counted finalizers still run.
    gc.freeze()
    if code == 130:
        # A Ctrl-C that passed through a C extension's embedded Python (pybind11 exec in open3d) marks the
        # interpreter as "interrupted"; it would then end itself with SIGINT instead of exit code 130. Outputs
        # were already cleaned by the handlers on the way out, so leave at once with the code we promise.
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(130)
    sys.exit(code)


if __name__ == "__main__":
    main()
