"""The twin's side of the operator socket: it places each trial's object and presses the operator's keys.

JSON lines over a Unix socket (the host's side is `envs/operator.py:SocketOperator`):

    host -> twin   {"op": "place", "object": NAME, "seed": S, "token": N}   the host homed; trial N wants NAME
                   {"op": "ask", "token": N}                                 the time limit: was it a success?
                   {"op": "end", "token": N}                                 the trial is over
                   {"op": "hand", "q": [9 rad] | null}                       hold the joints there by hand / let go
                   {"op": "weight", "tip": K | null, "mass_kg": M}           rest a weight on pad K alone / take it off
                   {"op": "status"}                                          the twin's timing and counters
    twin -> host   {"judge": TEXT}                                           once, on connect
                   {"key": "enter" | "s" | "f" | "y" | "n", "token": N}      the operator's keys for trial N
                   {"ok": true, ...}                                          replies to hand / status

At most one outcome key goes out per trial, carrying its trial's token, so a key of a finished trial can never
decide the next one. A host that leaves without an "end" aborted its trial: a failure with `"aborted": true`.
"""

from __future__ import annotations

import json
import logging
import os
import socket
import threading
import time

from lerobot_blindgrasp import durable, spec

logger = logging.getLogger(__name__)

JUDGE = (
    f"twin (the sim's rule: lifted >= {spec.SUCCESS_LIFT_M * 100:.1f} cm for {spec.SUCCESS_HOLD_S:g} s, "
    "judged in the twin's physics)"
)


class OperatorServer:
    def __init__(self, path: str, twin, trial_log: str | None = None, empty_claw_after_s: float = 3.0):
        self.path, self.twin, self.trial_log = path, twin, trial_log
        self.empty_claw_after_s = empty_claw_after_s
        if os.path.exists(path):
            os.unlink(path)  # a socket file left by a killed twin
        self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self._sock.bind(path)
        self._sock.listen(4)
        self._lock = threading.Lock()
        self._active: tuple[socket.socket, int, dict] | None = None  # (connection, token, placement)
        self._verdicts: dict[int, tuple[bool, str]] = {}  # physics trial -> (success, reason)
        self._aborted: set[int] = set()  # tokens of trials whose host left before ending them
        self._stop = threading.Event()
        twin.physics.on_verdict = self._on_verdict

    def start(self) -> OperatorServer:
        threading.Thread(target=self._accept, name="twin-operator", daemon=True).start()
        return self

    def stop(self) -> None:
        self._stop.set()
        try:
            self._sock.close()
        finally:
            if os.path.exists(self.path):
                os.unlink(self.path)

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self._sock.accept()
            except OSError:
                return
            threading.Thread(target=self._serve, args=(conn,), name="twin-operator-client", daemon=True).start()

    @staticmethod
    def _send(conn: socket.socket, msg: dict) -> None:
        try:
            conn.sendall((json.dumps(msg) + "\n").encode())
        except OSError:
            pass  # the host went away; its next connection starts afresh

    def _serve(self, conn: socket.socket) -> None:
        self._send(conn, {"judge": JUDGE})
        with conn, conn.makefile("rb") as lines:
            for line in lines:
                try:
                    msg = json.loads(line)
                    reply = self._handle(conn, msg)
                except (ValueError, KeyError, TypeError) as e:
                    reply = {"ok": False, "error": f"{type(e).__name__}: {e}"}
                if reply is not None:
                    self._send(conn, reply)
        self._host_left(conn)
        # A few seconds after the host went away the operator empties the claw for the next session; not at once:
        # what the gripper does to the object right after its host died is part of the trial.
        timer = threading.Timer(self.empty_claw_after_s, self._finish_abandoned, args=(conn,))
        timer.daemon = True
        timer.start()

    def _host_left(self, conn: socket.socket) -> None:
        """The host left without ending its trial (SIGTERM, a safety stop, a crash). Judging stops now, so a lift
        the physics completes after the host let go can never become a success."""
        with self._lock:
            active = self._active if self._active is not None and self._active[0] is conn else None
            if active is not None:
                self._aborted.add(active[1])
        if active is not None:
            with self.twin.physics.lock:
                if self.twin.physics.trial == active[2]["trial"]:
                    self.twin.physics.judging = False

    def _finish_abandoned(self, conn: socket.socket) -> None:
        with self._lock:
            token = self._active[1] if self._active is not None and self._active[0] is conn else None
        if token is not None:
            self._finish(token)

    def _handle(self, conn: socket.socket, msg: dict) -> dict | None:
        op = msg["op"]
        if op == "place":
            placement = self.twin.physics.place(msg["object"], int(msg["seed"]))
            with self._lock:
                self._active = (conn, int(msg["token"]), placement)
            return {"key": "enter", "token": int(msg["token"]), "placement": placement}
        if op == "ask":
            return self._answer(int(msg["token"]))
        if op == "end":
            self._finish(int(msg["token"]))
            return None
        if op == "hand":
            self.twin.physics.hold_by_hand(msg["q"])
            return {"ok": True}
        if op == "weight":
            self.twin.physics.place_weight(msg["tip"], float(msg.get("mass_kg", 0.0)))
            return {"ok": True}
        if op == "status":
            return {"ok": True, **self.twin.status()}
        raise ValueError(f"unknown op {op!r}")

    def _on_verdict(self, verdict) -> None:
        with self._lock:
            self._verdicts[verdict.trial] = (verdict.success, verdict.reason)
            active = self._active
        if active is not None and active[2]["trial"] == verdict.trial:
            self._send(active[0], {"key": "s" if verdict.success else "f", "token": active[1]})

    def _answer(self, token: int) -> dict:
        with self._lock:
            trial = self._active[2]["trial"] if self._active and self._active[1] == token else None
            if trial is not None and trial not in self._verdicts:
                success = self.twin.physics.verdict_now()
                self._verdicts[trial] = (success, "time limit")
                self.twin.physics.end_trial()
            success = self._verdicts.get(trial, (False, ""))[0]
        return {"key": "y" if success else "n", "token": token}

    def _finish(self, token: int) -> None:
        with self._lock:
            active, self._active = self._active, None
        self.twin.physics.end_trial()
        if active is None or active[1] != token:
            return
        placement = active[2]
        success, reason = self._verdicts.get(placement["trial"], (False, "host ended the trial first"))
        aborted = token in self._aborted
        if aborted:  # never a success, whatever the physics judged: the host's protocol did not finish the trial
            judged = placement["trial"] in self._verdicts
            verdict = f"{'success' if success else 'failure'} ({reason})" if judged else None
            success, reason = False, f"host aborted the trial (left without ending it); physics verdict: {verdict}"
        record = {
            **placement,
            "success": success,
            "aborted": aborted,
            "reason": reason,
            "judge": "twin",
            "peak_lift_m": round(self.twin.physics.peak_lift, 4),
            "peak_tip_force_n": [round(float(f), 2) for f in self.twin.physics.peak_tip_force_n],
            "held_tip_force_n": [round(float(f), 2) for f in self.twin.physics.held_tip_force_n],
            "q_at_peak_rad": [round(float(q), 3) for q in self.twin.physics.q_at_peak],
            "t_end": round(time.time(), 2),
        }
        logger.info("trial %s: %s (%s)", placement["trial"], "SUCCESS" if success else "failure", reason)
        if self.trial_log:
            durable.atomic_append_text(self.trial_log, json.dumps(record) + "\n")
