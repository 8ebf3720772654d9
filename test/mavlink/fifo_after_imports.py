"""`python fifo_after_imports.py PRIO MODULE [ARGS...]`: runs `python -m MODULE ARGS...` at
SCHED_FIFO PRIO, its imports done first at the normal priority.

The link's processes (simulated autopilot, router) run above mppid as the bridge does in
service (mavchain.py): short I/O work. Their start is not short: a second or so of importing
pymavlink, numpy and lcm, which at SCHED_FIFO 85 held off everything below it on that core, a
real-time mppid of another test worker included (its loop pinned there missed half a second
of cycles and the vehicle fell). So they import first, then take their priority, as the
bridge's `--realtime` does itself (mppi_mavlink/realtime.py)."""
import importlib
import os
import runpy
import sys


def main() -> None:
    prio, module = int(sys.argv[1]), sys.argv[2]
    spec = importlib.util.find_spec(module)
    if spec is None:
        sys.exit(f"fifo_after_imports.py: no module {module!r}")
    # The module's own imports (a package: its __main__, whose main() runs only as __main__).
    main_name = module + ".__main__" if spec.submodule_search_locations else module
    importlib.import_module(main_name)
    sys.modules.pop(main_name, None)  # run afresh as __main__ below; what it imported stays loaded
    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(prio))
    sys.argv = [module, *sys.argv[3:]]
    runpy.run_module(module, run_name="__main__", alter_sys=True)


if __name__ == "__main__":
    main()
