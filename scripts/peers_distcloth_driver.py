"""``distcloth run`` with the stepping loop timed, for scripts/bench_peers.py.

    scripts/mpiexec.sh 2 .venv/bin/python scripts/peers_distcloth_driver.py --save T.json -- \
        configs/bench/s1_41.yaml --set time.step=0.005 --output X.h5 --overwrite --quiet

Runs distcloth's own command line unchanged; distcloth.run.write_steps (the
loop over the steps, output frames included) is wrapped in a timer, and
rank 0 writes {"stepping_s": ..., "code": ...} to --save.
"""
import json
import sys
import time

import distcloth.run as run_module
from distcloth.cli import main as cli_main


def main():
    argv = sys.argv[1:]
    cut = argv.index("--")
    save = argv[argv.index("--save") + 1]
    timed = {"stepping_s": 0.0, "steps_called": 0}
    write_steps = run_module.write_steps

    def timed_write_steps(*args, **kwargs):
        t0 = time.perf_counter()
        try:
            return write_steps(*args, **kwargs)
        finally:
            timed["stepping_s"] += time.perf_counter() - t0
            timed["steps_called"] += 1

    run_module.write_steps = timed_write_steps
    code = cli_main(["run"] + argv[cut + 1:])
    from mpi4py import MPI
    if MPI.COMM_WORLD.rank == 0:
        with open(save, "w") as f:
            json.dump({**timed, "code": int(code or 0)}, f)
    return code


if __name__ == "__main__":
    sys.exit(main())
