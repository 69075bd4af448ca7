"""Start the simulators of a virtual bench: for :func:`labrig.runner.rigfile.open_rig` and for
``labrig sim serve`` (standalone, so a person can point the real drivers, a terminal or a Modbus
tool at them).

Started together, all on 127.0.0.1 (free ports unless given): the GCS responder (amplifier,
``socket://127.0.0.1:PORT``), the Modbus TCP server and the Modbus RTU-framed server (conditioner,
``127.0.0.1:PORT`` and ``socket://127.0.0.1:PORT``). The DAQ is in-process only; in ``serve``
the bench clock runs in real time with the DAQ output held at 0 V, so ``SVA`` in ONLINE mode
moves the output and ``VOL?`` follows it.

The simulated amplifier applies the rig's voltage limits from the start (VMI/VMA at the rig's
``v_min_V``/``v_max_V``, never beyond them). A fixed port that cannot be bound raises
:class:`SimulatorPortError` (exit 2, naming the rig file's ``simulator.*_port`` field).
"""

from __future__ import annotations

import errno
import threading
import time
from pathlib import Path

from labrig.drivers.sim.bench import BenchConfig, VirtualBench
from labrig.drivers.sim.gcs_server import GCSServer
from labrig.drivers.sim.modbus_server import ModbusConditionerServer

from labrig.core.errors import InputFileError, InputIssue, LabrigError
from labrig.core.interrupts import interrupt_once
from labrig.model.accel import kernels
from labrig.model.warm import warm as warm_model
from labrig.rig.limits import RigLimits
from labrig.rig.rigspec import RigSpec, load_rig

#: simulator kind -> the rig file's port field
PORT_FIELDS = {
    "gcs": "simulator.gcs_port",
    "modbus_tcp": "simulator.modbus_tcp_port",
    "modbus_rtu": "simulator.modbus_rtu_port",
}


class SimulatorPortError(LabrigError):
    """A simulator could not listen on its port (exit 2: the rig file names the port)."""

    exit_code = 2

    def __init__(self, kind: str, port: int, reason: str):
        self.kind, self.port, self.field = kind, port, PORT_FIELDS[kind]
        self.detail = (
            f"the {kind} simulator cannot listen on 127.0.0.1:{port} ({reason}); "
            "choose a free port, or 0 for any free one"
        )
        super().__init__(f"{self.field}: {self.detail}")


class Simulators:
    """A virtual bench and its protocol servers; ``endpoints`` maps kinds to addresses."""

    def __init__(
        self,
        config: BenchConfig | None = None,
        limits: RigLimits | None = None,
        seed: int | None = None,
        ports: dict[str, int] | None = None,
        axis: str = "A",
        channel: str = "1",
        unit: int = 1,
        conditioner_filter_hz: float | None = None,
    ):
        self.bench = VirtualBench(config, limits, seed)
        # a client may switch the conditioner's low-pass on at any time (None: unknown)
        self._filters = conditioner_filter_hz is None or self.bench.config.filters(
            conditioner_filter_hz
        )
        ports = ports or {}
        self.gcs = GCSServer(self.bench, port=ports.get("gcs", 0), axis=axis, channel=channel)
        self.modbus_tcp = ModbusConditionerServer(
            self.bench, "tcp", port=ports.get("modbus_tcp", 0), unit=unit
        )
        self.modbus_rtu = ModbusConditionerServer(
            self.bench, "rtu", port=ports.get("modbus_rtu", 0), unit=unit
        )
        self._started: list = []
        self._clock: threading.Thread | None = None
        self._clock_stop = threading.Event()

    def start(self) -> Simulators:
        # the truth's compiled kernels (when the bench runs them: numba already in the process,
        # labrig.model.accel.stream_engine), and scipy.signal when the bench filters (a second
        # of import CPU), loaded before any server answers: a first block or a filter setting
        # must not hold the bench past a driver's answer timeout
        if self.bench.engine == "compiled":
            warm_model()
        if self._filters:
            import scipy.signal  # noqa: F401
        kinds = {"gcs": self.gcs, "modbus_tcp": self.modbus_tcp, "modbus_rtu": self.modbus_rtu}
        try:
            for kind, srv in kinds.items():
                try:
                    srv.start()
                except OSError as e:
                    in_use = e.errno == errno.EADDRINUSE
                    why = "the port is in use" if in_use else (e.strerror or str(e))
                    raise SimulatorPortError(kind, srv.port, why) from None
                self._started.append(srv)
        except BaseException:
            self.stop()
            raise
        return self

    @property
    def endpoints(self) -> dict[str, str]:
        return {
            "gcs": self.gcs.url,
            "modbus_tcp": self.modbus_tcp.address,
            "modbus_rtu": self.modbus_rtu.address,
        }

    def run_clock(self, period_s: float = 0.05) -> None:
        """Advance the bench in real time (for standalone serving; not during DAQ playback)."""

        def tick():
            last = time.monotonic()
            while not self._clock_stop.wait(period_s):
                now = time.monotonic()
                self.bench.settle(now - last)
                last = now

        self._clock = threading.Thread(target=tick, name="bench-clock", daemon=True)
        self._clock.start()

    def stop(self) -> None:
        self._clock_stop.set()
        if self._clock is not None:
            self._clock.join(1.0)
        # the servers stop side by side: each bounds its own waits (a Modbus server's shutdown
        # can hang for its 2 s + 2 s), so the slowest, not their sum, sets how long Ctrl-C takes
        stoppers = [threading.Thread(target=srv.stop, daemon=True) for srv in self._started]
        for t in stoppers:
            t.start()
        for t in stoppers:
            t.join(5.0)
        self._started.clear()

    def describe(self) -> dict:
        d = self.bench.describe()
        d["endpoints"] = self.endpoints
        return d


def serve(rig_path: Path | None) -> None:
    """Start the simulators of a rig file's bench (default rig if None), print their addresses
    and run until Ctrl-C, SIGTERM, SIGHUP or SIGQUIT (each stops the servers and frees their
    ports)."""
    spec = load_rig(rig_path)
    with interrupt_once():
        # a server with no set end: its clock steps the bench 20 times a second for as long as
        # it runs, which repays numba's start within minutes (accel.stream_engine)
        kernels()
        try:
            sims = Simulators(
                spec.bench_config or BenchConfig(), spec.limits, spec.seed_hint, spec.sim_ports
            ).start()
        except SimulatorPortError as e:
            raise InputFileError([InputIssue(spec.source, None, e.field, e.detail)]) from None
        try:
            sims.run_clock()
            _print_addresses(spec.name, sims)
            while True:
                time.sleep(0.5)
        except KeyboardInterrupt:
            print("stopping the simulators", flush=True)
        finally:
            sims.stop()


def _print_addresses(rig_name: str, sims: Simulators) -> None:
    lo, hi = sims.bench.allowed_range_V
    ep = sims.endpoints
    print(f"labrig virtual bench for rig {rig_name!r} (truth: {sims.bench.config.truth.preset})")
    print(f"  amplifier output limits (VMI/VMA): {lo:g} to {hi:g} V (the rig's limits)")
    print(f"  amplifier (GCS, pyserial URL):     {ep['gcs']}")
    print(f"  conditioner (Modbus TCP):          {ep['modbus_tcp']}  unit 1")
    print(f"  conditioner (Modbus RTU framing):  {ep['modbus_rtu']}  unit 1")
    print("  try: python -m serial.tools.miniterm --eol LF " + ep["gcs"])
    print("Press Ctrl-C to stop.", flush=True)


def start_for_rig(spec: RigSpec, seed: int | None) -> Simulators:
    """The virtual bench and its servers started for the simulated rig ``spec`` (the
    amplifier's axis and channel and the conditioner's unit from its settings); a port that
    cannot be bound is an :class:`InputFileError` naming the rig file's field (exit 2)."""
    amp_s = spec.settings["amplifier"]
    try:
        return Simulators(
            spec.bench_config or BenchConfig(),
            spec.limits,
            seed,
            spec.sim_ports,
            axis=getattr(amp_s, "axis", "A"),
            channel=getattr(amp_s, "channel", "1"),
            unit=getattr(spec.settings["conditioner"], "unit", 1),
            conditioner_filter_hz=float(getattr(spec.settings["conditioner"], "filter_hz", 0)),
        ).start()
    except SimulatorPortError as e:
        raise InputFileError([InputIssue(spec.source, None, e.field, e.detail)]) from None
