"""GCS responder: the simulated E-503 amplifier with an E-517-style digital interface.

A TCP server on 127.0.0.1 that speaks the GCS 2.0 ASCII subset documented in
``docs/instruments.md`` (LF-terminated lines, three-letter mnemonics; multi-line answers end every
line but the last with a space before the LF). Reach it with pyserial:
``serial.serial_for_url("socket://127.0.0.1:PORT")``. The amplifier's state lives in the
:class:`~labrig.drivers.sim.bench.VirtualBench`.

Limits: VMI/VMA start at the rig's voltage limits and can be set only within them (error 17
beyond), so ``SVA`` beyond the rig's range is refused from the first command. Numbers are plain
decimals (``[+-]digits[.digits][e[+-]digits]``; ``1_0``, ``nan`` or ``0x10`` are syntax errors,
error 1). At most ``MAX_CONNECTIONS`` clients are served at once; a further client is
disconnected at once, and so is a client that sends more than ``MAX_LINE`` bytes without a
line end.

Faults for tests (:meth:`GCSServer.inject`), each for the next ``count`` matching commands:
``drop`` (close the connection after the command arrives, without executing it: a link dropped
mid-command), ``silent`` (execute, never answer), ``garble`` (execute, answer with damaged bytes).
"""

from __future__ import annotations

import contextlib
import logging
import math
import re
import socket
import threading
from collections import deque
from dataclasses import dataclass

log = logging.getLogger("labrig.sim.gcs")

#: clients served at once (one thread each); a further connection is closed at once
MAX_CONNECTIONS = 16
#: the longest command line (bytes) the simulator buffers; a client sending more without a line
#: end is disconnected (no GCS command is longer than a few dozen bytes)
MAX_LINE = 4096
#: a GCS number: plain decimal with an optional exponent (no underscores, nan, inf or hex)
_NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")

IDN = "labrig virtual bench, E-503 amplifier / E-517-style GCS interface (simulated), 0, 1.0.0"

#: GCS error codes used (PI numbering where PI has one)
ERRORS = {
    0: "no error",
    1: "parameter syntax error",
    2: "unknown command",
    15: "invalid axis or channel identifier",
    17: "parameter out of range",
}

HELP = [
    "*IDN? - identification",
    "ERR? - last error code (cleared on read)",
    "ONL {<ch> <0|1>} - 1: ONLINE (digital control, output = SVA), 0: OFFLINE (analog input)",
    "ONL? [{<ch>}] - control mode",
    "SVA {<axis> <V>} - digital setpoint (V), used in ONLINE mode",
    "SVA? [{<axis>}] - digital setpoint",
    "VOL? [{<ch>}] - output voltage (V)",
    "VMA {<ch> <V>} / VMA? [{<ch>}] - upper output limit (V)",
    "VMI {<ch> <V>} / VMI? [{<ch>}] - lower output limit (V)",
    "OVF? [{<axis>}] - 1 if the output was clipped or current-limited since the last OVF?",
    "SRG? <axis> 1 - status register: bit0 overflow now, bit1 over-temperature, bit2 ONLINE",
    "HLP? - this list",
]


@dataclass
class _Fault:
    kind: str
    count: int
    command: str | None


def _num(s: str) -> float:
    """A GCS number (ValueError unless it matches ``_NUMBER`` and is finite)."""
    if not _NUMBER.fullmatch(s):
        raise ValueError(s)
    x = float(s)
    if not math.isfinite(x):
        raise ValueError(s)
    return x


class GCSServer:
    """The responder; ``start()`` binds 127.0.0.1 (port 0: a free port), ``url`` for pyserial."""

    def __init__(
        self, bench, host: str = "127.0.0.1", port: int = 0, axis: str = "A", channel: str = "1"
    ):
        self.bench = bench
        self.host, self.port = host, port
        self.axis, self.channel = axis, channel
        self.error = 0
        self.received: deque[bytes] = deque(maxlen=1000)  # command lines received (tests)
        self._faults: list[_Fault] = []
        self._lock = threading.Lock()
        self._sock: socket.socket | None = None
        self._conns: set[socket.socket] = set()
        self._threads: list[threading.Thread] = []
        self._stopping = threading.Event()

    # -- lifecycle -------------------------------------------------------------------------------
    def start(self) -> GCSServer:
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind((self.host, self.port))
        s.listen(4)
        s.settimeout(0.2)
        self._sock = s
        self.port = s.getsockname()[1]
        t = threading.Thread(target=self._accept_loop, name="gcs-accept", daemon=True)
        t.start()
        self._threads.append(t)
        return self

    @property
    def url(self) -> str:
        return f"socket://{self.host}:{self.port}"

    def stop(self) -> None:
        self._stopping.set()
        if self._sock is not None:
            with contextlib.suppress(OSError):  # shutdown wakes the blocked accept()
                self._sock.shutdown(socket.SHUT_RDWR)
            self._sock.close()
        with self._lock:
            conns = list(self._conns)
        for c in conns:
            self._close(c)
        for t in self._threads:
            t.join(timeout=1.0)

    def inject(self, kind: str, count: int = 1, command: str | None = None) -> None:
        """Misbehave on the next ``count`` commands (whose mnemonic is ``command`` if given)."""
        if kind not in ("drop", "silent", "garble"):
            raise ValueError(f"unknown GCS fault {kind!r}")
        with self._lock:
            self._faults.append(_Fault(kind, count, command))

    def _take_fault(self, mnemonic: str) -> str | None:
        with self._lock:
            for f in self._faults:
                if f.command is None or f.command == mnemonic:
                    f.count -= 1
                    if f.count <= 0:
                        self._faults.remove(f)
                    return f.kind
        return None

    # -- connections -----------------------------------------------------------------------------
    def _accept_loop(self) -> None:
        while not self._stopping.is_set():
            try:
                conn, _ = self._sock.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            with self._lock:
                full = len(self._conns) >= MAX_CONNECTIONS
                if not full:
                    self._conns.add(conn)
            if full:
                log.warning("refusing a client: %d connections already", MAX_CONNECTIONS)
                with contextlib.suppress(OSError):
                    conn.close()
                continue
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            t = threading.Thread(target=self._serve, args=(conn,), name="gcs-conn", daemon=True)
            t.start()
            self._threads = [x for x in self._threads if x.is_alive()] + [t]

    def _close(self, conn: socket.socket) -> None:
        with self._lock:
            self._conns.discard(conn)
        with contextlib.suppress(OSError):
            conn.shutdown(socket.SHUT_RDWR)
        conn.close()

    def _serve(self, conn: socket.socket) -> None:
        buf = b""
        conn.settimeout(0.2)
        try:
            while not self._stopping.is_set():
                try:
                    data = conn.recv(4096)
                except TimeoutError:
                    continue
                if not data:
                    return
                buf += data
                if b"\n" not in buf and len(buf) > MAX_LINE:
                    log.warning("dropping a client: %d bytes without a line end", len(buf))
                    return
                while b"\n" in buf:
                    line, buf = buf.split(b"\n", 1)
                    self.received.append(line + b"\n")
                    mnemonic = line.split(b" ", 1)[0].decode("ascii", "replace").strip()
                    fault = self._take_fault(mnemonic)
                    if fault == "drop":
                        log.info("fault: dropping the link on %r", line)
                        return
                    reply = self.handle(line.decode("ascii", "replace").strip("\r"))
                    if reply is None or fault == "silent":
                        continue
                    if fault == "garble":
                        reply = _garble(reply)
                    conn.sendall(reply)
        except OSError:
            return
        finally:
            self._close(conn)

    # -- the command set -------------------------------------------------------------------------
    def handle(self, line: str) -> bytes | None:
        """Execute one command line; the answer bytes, or None for commands without answer."""
        parts = line.split()
        if not parts:
            return None
        cmd, args = parts[0], parts[1:]
        b = self.bench
        a = b.amp
        ax, ch = self.axis, self.channel
        try:
            if cmd == "*IDN?":
                return _lines([IDN])
            if cmd == "ERR?":
                code, self.error = self.error, 0
                return _lines([str(code)])
            if cmd == "HLP?":
                return _lines(HELP)
            if cmd in ("ONL?", "SVA?", "VOL?", "VMA?", "VMI?", "OVF?"):
                ident = ax if cmd in ("SVA?", "OVF?") else ch
                ids = args or [ident]
                if any(i != ident for i in ids):
                    return self._fail(15)
                with b.lock:
                    if cmd == "ONL?":
                        val = str(int(a.online))
                    elif cmd == "SVA?":
                        val = f"{a.sva_V:.4f}"
                    elif cmd == "VOL?":
                        val = f"{a.v_out:.4f}"
                    elif cmd == "VMA?":
                        val = f"{a.vma_V:.4f}"
                    elif cmd == "VMI?":
                        val = f"{a.vmi_V:.4f}"
                    else:
                        val = str(int(a.overflow_latch))
                        a.overflow_latch = a.forced_overload
                return _lines([f"{i}={val}" for i in ids])
            if cmd == "SRG?":
                if len(args) != 2 or args[1] != "1":
                    return self._fail(1)
                if args[0] != ax:
                    return self._fail(15)
                with b.lock:
                    bits = int(a.limiting) | int(a.over_temperature) << 1 | int(a.online) << 2
                return _lines([f"{ax} 1=0x{bits:X}"])
            if cmd in ("ONL", "SVA", "VMA", "VMI"):
                if not args or len(args) % 2:
                    return self._fail(1)
                ident = ax if cmd == "SVA" else ch
                pairs = list(zip(args[::2], args[1::2], strict=True))
                if any(i != ident for i, _ in pairs):
                    return self._fail(15)
                for _, val in pairs:
                    if cmd == "ONL":
                        if val not in ("0", "1"):
                            return self._fail(17 if val.lstrip("-").isdigit() else 1)
                        with b.lock:
                            a.online = val == "1"
                    else:
                        x = _num(val)
                        with b.lock:
                            lo, hi = b.allowed_range_V
                            if cmd == "SVA" and not a.vmi_V <= x <= a.vma_V:
                                return self._fail(17)
                            if cmd == "VMA" and not (a.vmi_V < x <= hi):
                                return self._fail(17)
                            if cmd == "VMI" and not (lo <= x < a.vma_V):
                                return self._fail(17)
                            setattr(a, {"SVA": "sva_V", "VMA": "vma_V", "VMI": "vmi_V"}[cmd], x)
                b.settle()
                return None
            return self._fail(2)
        except ValueError:
            return self._fail(1)

    def _fail(self, code: int) -> None:
        self.error = code
        return None


def _lines(lines: list[str]) -> bytes:
    """GCS answer: every line but the last ends with ' \\n', the last with '\\n'."""
    return (" \n".join(lines) + "\n").encode("ascii")


def _garble(reply: bytes) -> bytes:
    """Damage an answer as line noise would: flipped bits, the terminator kept."""
    body = bytearray(reply[:-1] or b"0")
    for i in range(0, len(body), 2):
        body[i] ^= 0x80 | 0x15
    return bytes(body) + b"\n"
