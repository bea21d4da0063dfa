"""Distributed task pools with receiver-initiated round-robin work stealing
for the BVH traversal of a collision phase.

EG07 tutorial, Part 1 §5.8.1-5.8.2.  The hierarchies
are replicated on every rank, so a test is four integers (obj1, node1, obj2,
node2) and a *task* is a small int64 array of tests
(distcloth/collision/traverse.py).  Every rank keeps

* its current stack (one resumable ``TraversalState``), run in chunks of at
  most ``chunk`` tests; between chunks it polls for messages;
* a local task pool ``pool`` (a deque of (k, 4) arrays).  Initially one task
  per top-level test the rank owns.  The rank executes the *newest* task of
  its pool (LIFO, locality) and gives thieves the *oldest* one (the one
  closest to the root, i.e. carrying the most work).

Task creation (proactive, independent of requests): after a chunk, while the
stack holds more than tau = a*sigma + b tests (sigma = pool size), a new
task takes int(tau/2) (at least 1) tests from the bottom of the stack
(``take_bottom``: the tests closest to the root) into the pool.

Stealing (receiver initiated, round robin): a rank whose stack and pool are
empty sends a steal request to the next victim in the order rank+1, rank+2,
... (mod P, itself skipped; the pointer advances after every request).  The
victim answers between two of its chunks with the oldest task of its pool,
or with a refusal if the pool is empty; a refused thief asks the next
victim (after a full round of refusals it backs off briefly, doubling from
10 us up to 200 us; while waiting, idle ranks yield the core and then nap,
so they do not take CPU from busy ones when the ranks oversubscribe the
cores).  A thief has at most one request
outstanding.  The stolen tests go straight onto the thief's (empty) stack
and at least one chunk of them runs before the thief polls again, so a task
never bounces between ranks without progress.

Messages go over a communicator duplicated once per parent communicator
(``comm.mpi_comm.Dup()``, collective on the first stealing call), never mixing
with other traffic.  Each call is an *epoch*; the tag of a message is
``kind + 16 * (epoch mod 2048)`` and its first payload word is the epoch;
receiving a message of another epoch raises (it cannot happen: every
message of a phase is received before the phase returns, see below).

Termination (Dijkstra-Safra, EWD998, with message counters)
----------------------------------------------------------
*Basic* messages are the task transfers (a steal answer carrying tests): a
rank is **active** while its stack or pool is non-empty and **passive**
otherwise; a passive rank becomes active only by receiving a task, and only
an active rank sends one (it takes it from its non-empty pool).  Requests
and refusals are control messages: they never change who is active.

Each rank keeps ``count`` = tasks sent - tasks received and a colour:
receiving a task makes it black.  Rank 0, when passive, starts a probe: it
turns white and sends the token (q = 0, white) to rank 1.  A rank i > 0
holding the token forwards it to i+1 mod P only when passive, adding its
count to q, blackening the token if it is black itself, and turns white.
When the token is back at rank 0 and rank 0 is passive, the computation has
terminated iff the token is white, rank 0 is white and q + count_0 == 0;
otherwise rank 0 starts a new probe.

Proof sketch (EWD998).  Let B be the number of tasks in flight; P0: B =
sum_i count_i at every instant.  During a probe let V be the set of ranks
the token has left (ranks 1..t).  Invariant: P0 and (Pa or Pb or Pc or Pd),
Pa: every rank in V is passive and q = sum_{i in V} count_i;
Pb: sum_{i not in V} count_i + q > 0;
Pc: some rank not in V is black;   Pd: the token is black.
A fresh probe has V empty and q = 0 (Pa).  Sending a task (by an active
rank, hence not in V while Pa holds) only raises a count.  A receipt by a
rank r outside V blackens r (Pc).  A receipt by r in V may falsify Pa; but
if Pa held, sum_{not V} count_i + q = B >= 1 before the receipt, so Pb held
and still holds after it (only count_r, r in V, changed); Pb itself is only
falsified by receipts outside V, which make Pc true.  Forwarding the token
(by a passive rank i not in V) adds count_i to q as i joins V (Pa, Pb
preserved) and i's colour to the token before i turns white (Pc -> Pd).
When the probe ends at rank 0 (the only rank not in V) with the token
white, rank 0 white and q + count_0 = 0, Pb, Pc and Pd are false, so Pa
holds: ranks 1..P-1 are passive and B = q + count_0 = 0; rank 0 is passive
as well, so nobody holds a test and none is in flight; nobody can become
active again (stable).  Liveness: the total number of tests is finite and
fixed (every test's children are determined by the test, not by where it
runs) and every transfer is followed by at least one executed test, so
eventually all ranks are passive with B = 0; a passive rank forwards the
token at its next poll, so the first full round after that whitens every
rank and the next one detects termination.

No lost or duplicated test: a test row lives in exactly one place (a stack,
a pool or one task message) and moves only by pop-and-execute, take_bottom
(stack -> pool), popleft-and-send (pool -> message) and receive (message ->
stack); at termination no place holds a row, so every test ran exactly once
and (module docstring of traverse.py) the union of the result rows equals
the serial result, each row emitted once.

Draining.  Rank 0 then sends STOP to every other rank; a rank leaves the
main loop on STOP (it is passive; no task can reach it any more) and stops
issuing requests.  Requests and refusals may still be in flight, so the
ranks exchange how many requests each sent to each other rank
(``Alltoall`` on the private communicator: every rank gets there since
STOP always arrives) and every rank polls until it has received and refused
every request addressed to it and got the answer to its own outstanding
request (those are already sent or answered by a rank in the same loop),
then waits for all its own sends, and the ranks meet in a barrier.  So when
``run_tasks`` returns no message of the epoch is unreceived or pending, and
the barrier keeps a fast rank from sending a request of the next epoch to
a rank still polling in this one (the polls take any tag; a message of
another epoch is detected by its tag and epoch word and raises).

``stealing=False`` runs the static assignment: every rank traverses exactly
its own top-level tests; no messages at all (so it is not collective).
"""
from __future__ import annotations

import os
import time
from collections import deque

import numpy as np
from mpi4py import MPI

from ..collision.traverse import TraversalState, as_forest

REQ, TASK, REFUSE, TOKEN, STOP = 1, 2, 3, 4, 5
_KINDS = 16
_EPOCHS = 2048

__all__ = ["run_tasks", "summarize", "StealTimeout"]


class StealTimeout(RuntimeError):
    """``run_tasks`` ran longer than its ``timeout`` (a watchdog for tests)."""


class _Channel:
    """The private communicator of one parent communicator, and the epoch."""

    def __init__(self, mpi_comm):
        self.comm = mpi_comm.Dup()
        self.epoch = 0


_CHANNELS: dict = {}


def _channel(mpi_comm) -> _Channel:
    key = mpi_comm.py2f()
    ch = _CHANNELS.get(key)
    if ch is None:
        ch = _CHANNELS[key] = _Channel(mpi_comm)
    return ch


def _mpi_of(comm):
    """(mpi4py communicator, MPI module) of a distcloth Comm or an mpi4py Comm."""
    return getattr(comm, "mpi_comm", comm), MPI


def run_tasks(comm, forest, tests, owner, *, stealing: bool = True, a: float = 2.0, b: float = 8,
              chunk: int = 256, delay: float | None = None, delay_prob: float = 0.25,
              seed: int = 0, timeout: float | None = None):
    """Run the top-level tests ``tests`` (n, 4) of the replicated ``forest``
    (a Forest or a list of BVHs, identical on every rank), the test i
    starting in the pool of rank ``owner[i]``.

    Collective when ``stealing`` (every rank calls it with the same tests,
    owner and parameters); with ``stealing=False`` every rank just runs its
    own tests (static assignment, no communication).

    a, b: task creation threshold tau = a * sigma + b (EG07 tutorial,
    Part 1 §5.8.2: a = 2, b = 8); chunk: tests per traversal chunk between two polls; delay: test
    mode, sleep uniform(0, delay) seconds with probability delay_prob before
    each chunk, each steal request and each answer (random, seeded by seed,
    rank and epoch); timeout: raise StealTimeout after that many seconds.

    Returns (rows, stats): the result rows (k, 4) int64 (obj1, p1, obj2, p2)
    found on this rank (the union over ranks is the serial result, every row
    on exactly one rank) and this rank's statistics: wall, busy (thread CPU
    time inside traversal chunks), idle (wall - busy), tests (executed
    here), rows (result rows found here), tasks_initial, tasks_run,
    tasks_created, tasks_stolen (received), tasks_given, steals_refused
    (refusals received), refusals_sent, requests_sent, requests_received,
    msgs_sent, msgs_received, tokens (token messages sent),
    steal_latency_mean / _max (s, request sent -> answer received), epoch.

    If it raises (StealTimeout, an MPI error) messages of the phase may be
    left unreceived: the caller should abort rather than call it again.
    """
    forest = as_forest(forest)
    tests = np.ascontiguousarray(tests, dtype=np.int64).reshape(-1, 4)
    owner = np.asarray(owner, dtype=np.int64).reshape(-1)
    if owner.shape[0] != tests.shape[0]:
        raise ValueError("run_tasks: owner must have one entry per test")
    mpi, MPI = _mpi_of(comm)
    rank = mpi.Get_rank()
    mine = tests[owner == rank]
    if not stealing:
        return _run_static(forest, mine, rank, chunk, delay, delay_prob, seed, timeout)
    phase = _Phase(_channel(mpi), MPI, forest, mine, float(a), float(b), int(chunk),
                   delay, delay_prob, seed, timeout)
    return phase.run()


def _new_stats(rank, n_initial) -> dict:
    keys = ("tests", "rows", "tasks_run", "tasks_created", "tasks_stolen", "tasks_given",
            "steals_refused", "refusals_sent", "requests_sent", "requests_received",
            "msgs_sent", "msgs_received", "tokens")
    s = {k: 0 for k in keys}
    s.update(rank=rank, tasks_initial=int(n_initial), wall=0.0, busy=0.0, idle=0.0,
             steal_latency_mean=0.0, steal_latency_max=0.0, epoch=0)
    return s


def _run_static(forest, mine, rank, chunk, delay, delay_prob, seed, timeout):
    t0 = time.perf_counter()
    stats = _new_stats(rank, mine.shape[0])
    rng = np.random.default_rng([seed, rank]) if delay else None
    state = TraversalState(mine)
    busy = 0.0
    while state.top > 0:
        if rng is not None and rng.random() < delay_prob:
            time.sleep(rng.uniform(0.0, delay))
        c0 = time.thread_time()
        state.run(forest, chunk)
        busy += time.thread_time() - c0
        if timeout is not None and time.perf_counter() - t0 > timeout:
            raise StealTimeout(f"rank {rank}: static traversal exceeded {timeout} s")
    stats["tests"] = int(state.tests_run)
    stats["rows"] = int(state.n_out)
    stats["tasks_run"] = int(mine.shape[0])
    stats["busy"] = busy
    stats["wall"] = time.perf_counter() - t0
    stats["idle"] = max(0.0, stats["wall"] - busy)
    return state.pairs().copy(), stats


class _Phase:
    """One collision phase on one rank (the state machine of the module docstring)."""

    def __init__(self, channel, MPI, forest, mine, a, b, chunk, delay, delay_prob, seed, timeout):
        self.MPI = MPI
        self.comm = channel.comm
        channel.epoch += 1
        self.epoch = channel.epoch
        self.tagbase = _KINDS * (self.epoch % _EPOCHS)
        self.rank = self.comm.Get_rank()
        self.size = self.comm.Get_size()
        self.forest = forest
        self.a, self.b, self.chunk = a, b, max(1, chunk)
        self.timeout = timeout
        self.delay, self.delay_prob = delay, delay_prob
        self.rng = np.random.default_rng([seed, self.rank, self.epoch]) if delay else None
        self.pool = deque(mine[i:i + 1].copy() for i in range(mine.shape[0]))
        self.state = TraversalState(np.zeros((0, 4), np.int64))
        self.stats = _new_stats(self.rank, mine.shape[0])
        self.stats["epoch"] = self.epoch
        # Safra
        self.count = 0                 # tasks sent - tasks received
        self.black = False
        self.token = None              # (q, black) while held
        self.probe_running = False     # rank 0 only
        self.stop = False
        # stealing
        self.victim = (self.rank + 1) % self.size
        self.outstanding = None        # (victim, time sent, seq)
        self.seq = 0
        self.refusals_in_row = 0
        self.backoff = 0.0
        self.next_request = 0.0
        self.req_sent_to = np.zeros(self.size, np.int64)
        self.req_recv_from = np.zeros(self.size, np.int64)
        self.latencies = []
        self.sends = []                # (MPI request, buffer) not known complete
        self.empty_polls = 0
        self.status = MPI.Status()

    # ------------------------------------------------------------ helpers
    def _nap(self, p=None):
        if self.rng is not None and self.rng.random() < (self.delay_prob if p is None else p):
            time.sleep(self.rng.uniform(0.0, self.delay))

    def _send(self, kind, dest, payload):
        buf = np.ascontiguousarray(payload, dtype=np.int64)
        req = self.comm.Isend(buf, dest=dest, tag=self.tagbase + kind)
        self.sends.append((req, buf))
        self.stats["msgs_sent"] += 1
        if len(self.sends) > 64:
            self.sends = [(r, bb) for r, bb in self.sends if not r.Test()]

    def _check_time(self, t0):
        if self.timeout is not None and time.perf_counter() - t0 > self.timeout:
            raise StealTimeout(
                f"rank {self.rank} epoch {self.epoch}: no termination after {self.timeout} s "
                f"(stop={self.stop}, top={self.state.top}, pool={len(self.pool)}, "
                f"outstanding={self.outstanding}, token={self.token}, count={self.count}, "
                f"requests sent {self.req_sent_to.tolist()} "
                f"received {self.req_recv_from.tolist()})")

    def _idle_wait(self):
        """Nothing arrived: yield the core (a no-op unless the ranks
        oversubscribe the cores, where it lets the busy ranks run), and after
        a few hundred empty polls nap briefly (10 us doubling up to 160 us)."""
        self.empty_polls += 1
        if self.empty_polls <= 256:
            os.sched_yield()
        else:
            time.sleep(1e-5 * 2.0 ** min((self.empty_polls - 256) // 16, 4))

    def _load(self, task):
        st = self.state
        k = task.shape[0]
        if st.stack.shape[0] < k + 4:
            st.stack = np.empty((max(2 * k + 4, 2 * st.stack.shape[0]), 4), np.int64)
        st.stack[:k] = task[::-1]
        st.top = k
        self.stats["tasks_run"] += 1

    @property
    def passive(self) -> bool:
        return self.state.top == 0 and not self.pool

    # ---------------------------------------------------------------- run
    def run(self):
        t0 = time.perf_counter()
        st = self.state
        while not self.stop:
            if st.top > 0:
                self._work()
            elif self.pool:
                self._load(self.pool.pop())
                continue
            self._poll()
            if self.passive and not self.stop:
                self._idle()
            self._check_time(t0)
        self._drain(t0)
        s = self.stats
        s["wall"] = time.perf_counter() - t0
        s["idle"] = max(0.0, s["wall"] - s["busy"])
        s["tests"] = int(st.tests_run)
        s["rows"] = int(st.n_out)
        if self.latencies:
            s["steal_latency_mean"] = float(np.mean(self.latencies))
            s["steal_latency_max"] = float(np.max(self.latencies))
        return st.pairs().copy(), s

    def _work(self):
        if self.rng is not None:
            self._nap()
        st = self.state
        c0 = time.thread_time()
        st.run(self.forest, self.chunk)
        self.stats["busy"] += time.thread_time() - c0
        while True:                                  # task creation, tau = a sigma + b
            tau = self.a * len(self.pool) + self.b
            if st.top <= tau:
                break
            k = max(1, int(tau / 2))
            self.pool.append(st.take_bottom(k))
            self.stats["tasks_created"] += 1

    def _idle(self):
        """Passive: move the token, detect termination, steal."""
        if self.size == 1:
            self.stop = True
            return
        if self.rank == 0:
            if self.token is not None:               # the probe is back
                q, tblack = self.token
                self.token = None
                self.probe_running = False
                if not tblack and not self.black and q + self.count == 0:
                    for r in range(1, self.size):
                        self._send(STOP, r, [self.epoch])
                    self.stop = True
                    return
            if not self.probe_running:
                self.black = False
                self.probe_running = True
                self._send(TOKEN, 1, [self.epoch, 0, 0])
                self.stats["tokens"] += 1
        elif self.token is not None:
            q, tblack = self.token
            self.token = None
            self._send(TOKEN, (self.rank + 1) % self.size,
                       [self.epoch, q + self.count, int(tblack or self.black)])
            self.black = False
            self.stats["tokens"] += 1
        if self.outstanding is None:
            now = time.perf_counter()
            if now >= self.next_request:
                if self.rng is not None:
                    self._nap()
                v = self.victim
                self.seq += 1
                self._send(REQ, v, [self.epoch, self.seq])
                self.outstanding = (v, time.perf_counter(), self.seq)
                self.req_sent_to[v] += 1
                self.stats["requests_sent"] += 1
                self.victim = (v + 1) % self.size
                if self.victim == self.rank:
                    self.victim = (self.victim + 1) % self.size
                return
        self._idle_wait()

    # ----------------------------------------------------------- messages
    def _poll(self) -> int:
        """Receive and handle every message that has arrived; returns how many."""
        MPI = self.MPI
        n = 0
        while self.comm.Iprobe(source=MPI.ANY_SOURCE, tag=MPI.ANY_TAG, status=self.status):
            src = self.status.Get_source()
            tag = self.status.Get_tag()
            buf = np.empty(self.status.Get_count(MPI.INT64_T), np.int64)
            self.comm.Recv(buf, source=src, tag=tag)
            n += 1
            self.stats["msgs_received"] += 1
            kind = tag - self.tagbase
            if not 0 < kind < _KINDS or buf.shape[0] < 1 or buf[0] != self.epoch:
                raise RuntimeError(f"rank {self.rank}: stale message (tag {tag}, epoch "
                                   f"{buf[0] if buf.size else '?'}) in epoch {self.epoch}")
            if kind == REQ:
                self._answer(src, int(buf[1]))
            elif kind in (TASK, REFUSE):
                self._answered(src, kind, buf)
            elif kind == TOKEN:
                if self.token is not None or self.stop:
                    raise RuntimeError(f"rank {self.rank}: unexpected token")
                self.token = (int(buf[1]), bool(buf[2]))
            elif kind == STOP:
                if src != 0 or not self.passive:
                    raise RuntimeError(f"rank {self.rank}: STOP while active")
                self.stop = True
        if n:
            self.empty_polls = 0
        return n

    def _answer(self, thief, seq):
        self.req_recv_from[thief] += 1
        self.stats["requests_received"] += 1
        if self.rng is not None:
            self._nap()
        if self.pool and not self.stop:
            task = self.pool.popleft()                 # the oldest: closest to the root
            self._send(TASK, thief, np.concatenate([[self.epoch, seq], task.reshape(-1)]))
            self.count += 1
            self.stats["tasks_given"] += 1
        else:
            self._send(REFUSE, thief, [self.epoch, seq])
            self.stats["refusals_sent"] += 1

    def _answered(self, victim, kind, buf):
        if self.outstanding is None or self.outstanding[0] != victim \
                or self.outstanding[2] != int(buf[1]):
            raise RuntimeError(f"rank {self.rank}: unexpected steal answer from {victim}")
        self.latencies.append(time.perf_counter() - self.outstanding[1])
        self.outstanding = None
        if kind == TASK:
            if not self.passive or self.stop:
                raise RuntimeError(f"rank {self.rank}: task received while active")
            self.count -= 1
            self.black = True
            self._load(buf[2:].reshape(-1, 4))
            self.stats["tasks_stolen"] += 1
            self.refusals_in_row = 0
            self.backoff = 0.0
            self.next_request = 0.0
        else:
            self.stats["steals_refused"] += 1
            self.refusals_in_row += 1
            if self.refusals_in_row >= self.size - 1:   # a full round: back off
                self.refusals_in_row = 0
                self.backoff = min(2e-4, max(1e-5, 2.0 * self.backoff))
                self.next_request = time.perf_counter() + self.backoff

    def _drain(self, t0):
        """After termination: receive every request still addressed to this
        rank (and refuse it) and the answer to its own outstanding request,
        then complete every send (module docstring)."""
        if self.size > 1:
            expected = np.empty(self.size, np.int64)
            self.comm.Alltoall(self.req_sent_to, expected)
            while self.outstanding is not None or np.any(self.req_recv_from < expected):
                if not self._poll():
                    self._idle_wait()
                self._check_time(t0)
        if self.sends:
            self.MPI.Request.Waitall([r for r, _ in self.sends])
            self.sends = []
        if self.size > 1:
            # nobody starts the next epoch (and sends its first request)
            # while a rank may still be polling in this one
            self.comm.Barrier()
        if self.pool or self.state.top:
            raise RuntimeError(f"rank {self.rank}: work left after termination")


def summarize(comm, stats: dict) -> dict:
    """Collective: the per-rank ``stats`` of a phase combined over the ranks:
    busy_max, busy_mean, rows_max, rows_mean, wall_max, idle_mean, the sums
    of the counters tests, tasks_created, tasks_stolen, steals_refused,
    requests_sent, msgs_sent and msgs_received, the mean of the mean latencies over ranks that stole and the
    max latency."""
    mpi, _ = _mpi_of(comm)
    every = mpi.allgather(stats)
    out = {"ranks": len(every)}
    busy = np.array([s["busy"] for s in every])
    out["busy_max"] = float(busy.max())
    out["busy_mean"] = float(busy.mean())
    nrows = np.array([s["rows"] for s in every])
    out["rows_max"] = int(nrows.max())
    out["rows_mean"] = float(nrows.mean())
    out["wall_max"] = float(max(s["wall"] for s in every))
    out["idle_mean"] = float(np.mean([s["idle"] for s in every]))
    for k in ("tests", "tasks_created", "tasks_stolen", "steals_refused", "requests_sent",
              "msgs_sent", "msgs_received"):
        out[k] = int(sum(s[k] for s in every))
    lat = [s["steal_latency_mean"] for s in every if s["requests_sent"]]
    out["steal_latency_mean"] = float(np.mean(lat)) if lat else 0.0
    out["steal_latency_max"] = float(max(s["steal_latency_max"] for s in every))
    return out
