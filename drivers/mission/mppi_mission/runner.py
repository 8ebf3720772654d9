"""Flies a mission: starts the flight (vehicles.py), then each leg's steps (plan.py) in turn,
handing the link the step's reference at the link's rate from a thread of its own (so a
blocking request to the bridge never lets the reference go stale), and shows progress: the
leg, how far along it is, the position error to the reference and, on paths, its RMS at speed.

Writes, when given a folder: mission.jsonl (one line per event: steps started and ended,
with their reference and epoch; a sample of the vehicle's position against the reference at
the link's rate) and mission_summary.json (per leg: done or why not, RMS error, time).
"""
from __future__ import annotations

import json
import math
import threading
import time
from pathlib import Path

import numpy as np

from . import plan as plan_mod
from . import reference
from .vehicles import FlightError


class Runner:
    def __init__(self, mission: plan_mod.Mission, link, seed: int = 1, out: Path | None = None, say=print):
        self.m, self.link, self.seed, self.say = mission, link, seed, say
        self.out = Path(out) if out else None
        self.log = open(self.out / "mission.jsonl", "w", buffering=1) if self.out else None
        self.lock = threading.Lock()
        self.step = None          # the Step being flown, its epoch (state clock, us)
        self.t0_us = 0
        self.trees = []
        self.err2 = []            # squared errors at speed, this step
        self.heading = 0.0        # rad, ENU: the yaw of the reference flown last
        self.stop = threading.Event()
        self.summary = {"mission": mission.name, "seed": seed, "legs": [], "outcome": None}
        self.start_kw = {}        # the link's start(): how it engages (the bridge's `offboard` by default)

    # ---- the reference, at the link's rate --------------------------------------------------
    def _publisher(self):
        """Each tick the current step; at the stop once more, so that a step set in the last
        tick (the hold of a refused mission) still reaches mppid before the tool exits."""
        period = 1.0 / self.link.tick_hz
        stopping = False
        while not stopping:
            stopping = self.stop.wait(period)
            with self.lock:
                step, t0 = self.step, self.t0_us
            if step is None:
                continue
            self.link.send(step.ref, t0, self.trees)
            if not stopping:
                self._sample(step, t0)

    def _sample(self, step, t0):
        """The newest state against the reference at that state's own time."""
        sampled = self.link.sampled()
        if sampled is None:
            return
        now, p = sampled
        t = (now - t0) * 1e-6
        r = reference.evaluate(step.ref, [t])[0][0]
        e = float(np.linalg.norm(p - r))
        if step.leg >= 0 and step.kind != "goal" and not step.transit and \
                t >= step.full_speed_at + self.m.settle and (step.duration is None or t <= step.duration):
            self.err2.append(e * e)
        self._write({"t_us": now, "leg": step.leg, "p": p.round(4).tolist(), "ref": r.round(4).tolist(), "err": e})

    def _set(self, step, t0_us):
        with self.lock:
            self.step, self.t0_us, self.err2 = step, t0_us, []
        self._write({"event": "step", "leg": step.leg, "kind": step.kind, "transit": step.transit, "ref": step.ref,
                     "t0_us": t0_us, "duration": step.duration})

    def _write(self, rec):
        if self.log is not None:
            self.log.write(json.dumps(rec) + "\n")

    # ---- the mission ----------------------------------------------------------------------
    def hold_here(self):
        """mppid holds where the vehicle is, facing where it faces (a mission's `yaw: hold`
        keeps that heading, so the hand-over turns nothing)."""
        p, h = self.link.position(), self.link.heading()
        if h is not None:
            self.heading = h
        ref = {"kind": "hold", "center": p.tolist(), "yaw": self.heading}
        self._set(plan_mod.Step(-1, "hold", ref, None), self.link.now_us())
        self.say(f"holding at ({p[0]:.2f}, {p[1]:.2f}, {p[2]:.2f}), heading {math.degrees(self.heading):.0f} deg")

    def run(self) -> dict:
        pub = threading.Thread(target=self._publisher, name="mission-publish", daemon=True)
        t_start = time.monotonic()
        try:
            self.link.wait_state()
            self.link.check_task(self.m.task)
            origin = self.link.position() if self.m.frame == "start" else np.zeros(3)
            self.trees = self.m.trees(origin[:2], self.seed)
            if self.trees:
                self.say(f"{len(self.trees)} virtual trees (seed {self.seed})")
            self._write({"event": "mission", "name": self.m.name, "seed": self.seed, "origin": origin.tolist(),
                         "trees": self.trees, "vehicle_radius": self.m.vehicle_radius, "clock": self.link.clock,
                         "settle": self.m.settle})
            pub.start()
            self.link.start(self.m.takeoff, self.hold_here, self.say, **self.start_kw)
            if self.step is None:
                self.hold_here()
            here = np.asarray(self.step.ref["center"], float)
            self.summary["outcome"] = self._fly_legs(here, origin)
            self.link.finish(self.m.land, self.say)
        except FlightError as e:
            self.summary["outcome"] = f"error: {e}"
            self.say(f"mission stopped: {e}")
        except KeyboardInterrupt:
            self.summary["outcome"] = "interrupted"
            if self.link.position() is not None:
                self.hold_here()  # a path in progress must not run on without the tool
                self.link.send(self.step.ref, self.t0_us, self.trees)
            self.say("mission interrupted: mppid holds where the vehicle was; land it with the bridge "
                     "(mppid-mavlink-bridge land) or hand it back to the autopilot")
        finally:
            self.stop.set()
            if pub.is_alive():
                pub.join(2)
            self.summary["wall_s"] = round(time.monotonic() - t_start, 2)
            self._write({"event": "end", **self.summary})
            if self.out:
                (self.out / "mission_summary.json").write_text(json.dumps(self.summary, indent=1))
            if self.log is not None:
                self.log.close()
        return self.summary

    def _fly_legs(self, here, origin) -> str:
        """The legs in turn: the outcome ('done', or which leg failed)."""
        for i in range(len(self.m.legs)):
            ok, here = self._fly_leg(i, here, origin)
            if not ok:
                return f"leg {i} failed"
        return "done"

    def _fly_leg(self, i, here, origin):
        kind = next(iter(self.m.legs[i]))
        res = {"leg": i, "kind": kind, "ok": False}
        rmse = []
        for step in plan_mod.steps(self.m, i, here, origin, self.heading):
            self._set(step, self.link.now_us())
            self.heading = step.ref["yaw"]
            ok, why = self._until_done(step, i)
            if not step.transit:
                with self.lock:
                    rmse += list(self.err2)
            if not ok:
                res["why"] = why
                break
            here = step.end
        else:
            res["ok"] = True
        if rmse:
            res["rmse"] = math.sqrt(sum(rmse) / len(rmse))
            res["rmse_samples"] = len(rmse)
        self.summary["legs"].append(res)
        self.say(f"leg {i + 1}/{len(self.m.legs)} {kind}: " + ("done" if res["ok"] else f"failed ({res['why']})")
                 + (f", RMS error {res['rmse']:.3f} m" if "rmse" in res else ""))
        return res["ok"], here

    def _until_done(self, step, i):
        """Waits for the step's end, printing progress once a second."""
        t0, next_say = self.t0_us, 0.0
        while True:
            time.sleep(0.05)
            now, p = self.link.now_us(), self.link.position()
            t = (now - t0) * 1e-6
            if step.kind == "goal":
                d = float(np.linalg.norm(p - np.asarray(step.ref["center"])))
                if d <= step.goal_radius:
                    return True, ""
                if t > step.timeout:
                    return False, f"goal not reached in {step.timeout:g} s ({d:.1f} m away)"
            elif (step.duration is not None and t >= step.duration) or self.reached_early(step, i, t, p):
                return True, ""
            if time.monotonic() >= next_say:
                next_say = time.monotonic() + 1.0
                self.say(self._progress(step, i, t, p))
                why = self.interrupted()
                if why:
                    return False, why

    def interrupted(self) -> str:
        """Why the mission cannot go on ('' it can), asked once a second during a step."""
        return ""

    def reached_early(self, step, i, t, p) -> bool:
        """Whether a path step ends before its reference does (at `t` s, the vehicle at `p`):
        never here."""
        return False

    def _progress(self, step, i, t, p):
        r = reference.evaluate(step.ref, [t])[0][0]
        head = f"leg {i + 1}/{len(self.m.legs)} {'transit' if step.transit else step.kind}"
        span = f"{t:5.1f}" + (f"/{step.duration:.1f} s" if step.duration else " s")
        with self.lock:
            rms = math.sqrt(sum(self.err2) / len(self.err2)) if self.err2 else None
        return (f"{head}: {span}  error {np.linalg.norm(p - r):.2f} m" + (f"  RMS {rms:.3f} m" if rms else "")
                + f"  at ({p[0]:.1f}, {p[1]:.1f}, {p[2]:.1f})")
