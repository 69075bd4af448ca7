"""The protocol-file schema (pydantic v2): what a protocol YAML file may contain.

Units are in the key names: ``_V`` volts, ``_hz`` hertz, ``_s`` seconds. Unknown keys are
refused (a misspelt key is an error, never silently ignored), numbers must be numbers (a quoted
``"100"`` is refused), and infinities / NaN are refused everywhere. docs/protocol.md is the
user-facing description of every field; keep the two in step.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    StringConstraints,
    ValidationInfo,
    field_validator,
    model_validator,
)

from labrig.core.metadata import MetadataError, check_value

Finite = Annotated[float, Field(allow_inf_nan=False)]
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]
#: entry names become HDF5 group names: a letter, then letters, digits and underscores
EntryName = Annotated[str, StringConstraints(pattern=r"^[A-Za-z][A-Za-z0-9_]{0,59}$")]
ColumnRef = (
    Annotated[str, StringConstraints(min_length=1, max_length=200)]
    | Annotated[int, Field(ge=0, le=10_000)]
)

STEP_KINDS = (
    "sine",
    "offset_sine",
    "vanishing",
    "hold",
    "ramp",
    "csv",
    "sweep",
    "triangle",
    "prbs",
    "multisine",
    "strain_sine",
    "strain_vanishing",
    "strain_csv",
)
#: step kinds that command a strain (ue) through a controller instead of a voltage
STRAIN_KINDS = ("strain_sine", "strain_vanishing", "strain_csv")
FilePath = Annotated[str, StringConstraints(min_length=1, max_length=4096)]
#: a metadata key (``metadata:``): an HDF5 dataset name (labrig.core.metadata.KEY_PATTERN)
MetaKey = Annotated[str, StringConstraints(pattern=r"^[A-Za-z][A-Za-z0-9_]{0,62}$")]
#: a metadata value: text (printable, at most 200 characters), a boolean, a whole or a
#: finite number (labrig.core.metadata.check_value)
MetaValue = (
    Annotated[str, StringConstraints(max_length=200, pattern=r"^[^\x00-\x1f\x7f]*$")]
    | bool
    | int
    | Finite
)
#: entry names that would collide with the run file's own groups
RESERVED_NAMES = frozenset({"run"})


class _Base(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)


class _StepBase(_Base):
    """Keys every step accepts."""

    name: EntryName | None = Field(
        None,
        description="entry name in the run file (sweeps: prefix); default: derived from the "
        "step, e.g. sine_100V_40Hz",
    )
    repeat: int = Field(1, ge=1, le=1000, description="run this step (a whole sweep) N times")
    rest_s: NonNegative | None = Field(
        None, description="0 V rest after each entry of this step (default: the protocol's)"
    )

    @model_validator(mode="after")
    def _not_reserved(self):
        if self.name is not None and self.name.lower() in RESERVED_NAMES:
            raise ValueError(f"name {self.name!r} is reserved in run files; choose another")
        return self


def _one_of_cycles_duration(step, what: str = "the step") -> None:
    if (step.cycles is None) == (step.duration_s is None):
        raise ValueError(f"give exactly one of cycles or duration_s for {what}")


class SineStep(_StepBase):
    """Unipolar sine ``V = A/2 (1 - cos 2 pi f t)``: starts at 0 V, peaks at ``amplitude_V``."""

    kind: Literal["sine"]
    amplitude_V: Positive = Field(description="peak voltage A (the sine swings 0..A)")
    frequency_hz: Positive
    cycles: Positive | None = Field(None, description="number of cycles (or give duration_s)")
    duration_s: Positive | None = Field(None, description="length in seconds (or give cycles)")

    @model_validator(mode="after")
    def _length(self):
        _one_of_cycles_duration(self)
        return self


class OffsetSineStep(_StepBase):
    """A sine around a bias with an envelope, reached by a recorded ramp and settle.

    Recorded in order: a raised-cosine ramp from 0 V to ``offset_V`` over ``ramp_s``, a hold
    at ``offset_V`` for ``settle_s``, the sine ``V = offset_V + e(t) A sin(2 pi f t)`` for
    ``T`` = ``cycles / f`` or ``duration_s``, then a raised-cosine ramp back to 0 V over
    ``ramp_s``. The envelope ``e``: ``constant`` 1, ``growing`` ``t/T`` (from zero),
    ``vanishing`` ``1 - t/T`` (to zero).
    """

    kind: Literal["offset_sine"]
    offset_V: Finite = Field(description="the bias the sine swings around (0: a bipolar sine)")
    amplitude_V: Positive = Field(description="A: the sine swings offset_V - A .. offset_V + A")
    frequency_hz: Positive
    cycles: Positive | None = Field(None, description="number of cycles (or give duration_s)")
    duration_s: Positive | None = Field(None, description="length in seconds (or give cycles)")
    envelope: Literal["constant", "growing", "vanishing"] = Field(
        "constant", description="constant: e = 1; growing: e = t/T; vanishing: e = 1 - t/T"
    )
    ramp_s: NonNegative = Field(
        0.5, description="raised-cosine ramp 0 V -> offset_V before, and back after (0: none)"
    )
    settle_s: NonNegative = Field(1.0, description="hold at offset_V before the sine")

    @model_validator(mode="after")
    def _length(self):
        _one_of_cycles_duration(self)
        return self


class _Envelope(_Base):
    """The vanishing envelope's keys, shared by ``vanishing`` (volts) and ``strain_vanishing``
    (ue): carrier frequency, decay time and shape."""

    frequency_hz: Positive = Field(description="carrier frequency")
    decay_s: Positive = Field(description="time from the first peak until the envelope is zero")
    shape: Literal["exponential", "linear"] = "exponential"
    tau_s: Positive | None = Field(
        None, description="exponential time constant (default decay_s/2)"
    )

    @model_validator(mode="after")
    def _tau_only_exponential(self):
        if self.tau_s is not None and self.shape != "exponential":
            raise ValueError("tau_s applies only to shape: exponential")
        return self


class VanishingStep(_StepBase, _Envelope):
    """Unipolar sine whose amplitude decays to zero over ``decay_s``, then 0 V for ``hold_s``.

    The first half cycle rises to the full ``amplitude_V`` (at ``t0 = 1/(2f)``); from there the
    envelope ``e(s)``, ``s = t - t0``, goes from 1 to exactly 0 at ``s = decay_s = T``: linear
    ``1 - s/T``, or exponential ``(exp(-s/tau) - exp(-T/tau)) / (1 - exp(-T/tau))`` (an
    exponential shifted so that it reaches zero at T). ``V = e(s) A/2 (1 - cos 2 pi f t)``.
    """

    kind: Literal["vanishing"]
    amplitude_V: Positive = Field(description="peak voltage at the start of the envelope")
    hold_s: NonNegative = Field(0.0, description="0 V hold recorded after the envelope")


class HoldStep(_StepBase):
    """A constant voltage for ``duration_s`` (ramped in from and out to 0 V)."""

    kind: Literal["hold"]
    voltage_V: Finite
    duration_s: Positive


class RampStep(_StepBase):
    """A straight line from ``from_V`` to ``to_V`` over ``duration_s``."""

    kind: Literal["ramp"]
    from_V: Finite = 0.0
    to_V: Finite
    duration_s: Positive


class CsvStep(_StepBase):
    """Arbitrary voltage samples read from a CSV file.

    ``path`` is relative to the protocol file. The file may have a header line (column names)
    and ``#`` comment lines; values are separated by commas (or by whitespace when a line has no
    comma). Without ``time_column`` or ``rate_hz`` the samples are taken to be at the protocol's
    rate; otherwise they are resampled onto it by linear interpolation.
    """

    kind: Literal["csv"]
    path: Annotated[str, StringConstraints(min_length=1, max_length=4096)]
    column: ColumnRef | None = Field(
        None, description="voltage column: header name or 0-based index (default: first)"
    )
    time_column: ColumnRef | None = Field(None, description="column of sample times (s)")
    rate_hz: Positive | None = Field(None, description="sample rate of the file's rows")
    scale: Finite = Field(1.0, description="multiply the values by this (e.g. amplifier gain)")

    @model_validator(mode="after")
    def _timebase(self):
        if self.time_column is not None and self.rate_hz is not None:
            raise ValueError("give time_column or rate_hz for a csv step, not both")
        if self.scale == 0:
            raise ValueError("scale must not be 0")
        return self


class SweepStep(_StepBase):
    """Sine steps for every amplitude x frequency pair.

    Order ``by_amplitude`` (default): for each amplitude in the order listed, every frequency in
    the order listed; ``by_frequency``: the other way round. With ``min_duration_s`` the cycle
    count grows at high frequencies so that each entry lasts at least that long.
    """

    kind: Literal["sweep"]
    amplitudes_V: list[Positive] = Field(min_length=1, max_length=1000)
    frequencies_hz: list[Positive] = Field(min_length=1, max_length=1000)
    cycles: Positive | None = None
    duration_s: Positive | None = None
    min_duration_s: Positive | None = Field(
        None, description="with cycles: at least this long (cycles = max(cycles, ceil(f T)))"
    )
    order: Literal["by_amplitude", "by_frequency"] = "by_amplitude"

    @model_validator(mode="after")
    def _length(self):
        _one_of_cycles_duration(self, "a sweep")
        if self.min_duration_s is not None and self.cycles is None:
            raise ValueError("min_duration_s goes with cycles (not with duration_s)")
        return self


class TriangleStep(_StepBase):
    """Triangle ``V = offset_V + A tri(f t)`` (``tri``: slopes +-4, between -1 and 1).

    ``start: bias`` (default): ``tri(0) = 0``, rising (a triangle in phase with ``sin``);
    ``start: low``: ``tri(0) = -1``, rising (with ``offset_V = A`` a unipolar triangle 0..2A
    from 0 V). The slope is ``+-4 A f`` everywhere, so the current is ``4 C_eff A f``.
    """

    kind: Literal["triangle"]
    amplitude_V: Positive = Field(description="A: the triangle swings offset_V - A .. offset_V + A")
    offset_V: Finite = Field(0.0, description="the bias it swings around (0: bipolar)")
    frequency_hz: Positive
    start: Literal["bias", "low"] = Field(
        "bias", description="bias: rising through offset_V at t = 0; low: rising from offset_V - A"
    )
    cycles: Positive | None = Field(None, description="number of cycles (or give duration_s)")
    duration_s: Positive | None = Field(None, description="length in seconds (or give cycles)")

    @model_validator(mode="after")
    def _length(self):
        _one_of_cycles_duration(self)
        return self


#: LFSR lengths (bits) a ``prbs`` step may use: period ``2**order - 1`` chips
PRBS_ORDERS = (3, 24)


class PrbsStep(_StepBase):
    """Pseudo-random binary sequence between ``offset_V - A`` and ``offset_V + A``.

    The bits are a maximal-length LFSR sequence (``scipy.signal.max_len_seq`` with its tap
    table, ``order`` bits, period ``2**order - 1`` chips) started from the state whose bits are
    those of ``seed``; bit 1 is the high level. Chip ``k`` lasts ``1/clock_hz`` from ``k /
    clock_hz``. Edges are **slew-limited**: each level change is a straight ramp lasting
    ``transition_s`` at the start of the chip (slope ``2 A / transition_s``, current ``2 C_eff A
    / transition_s``), so preflight checks exactly what the amplifier must follow.
    """

    kind: Literal["prbs"]
    amplitude_V: Positive = Field(description="A: the levels are offset_V - A and offset_V + A")
    offset_V: Finite = Field(0.0, description="the mid level (0: levels -A and +A)")
    clock_hz: Positive = Field(description="chip rate: the level may change every 1/clock_hz s")
    order: int = Field(
        10, ge=PRBS_ORDERS[0], le=PRBS_ORDERS[1], description="LFSR bits (period 2**order - 1)"
    )
    seed: int = Field(1, ge=1, description="LFSR start state, 1 .. 2**order - 1")
    transition_s: Positive = Field(
        description="length of each level change (a straight ramp); at most half a chip"
    )
    periods: int | None = Field(
        None, ge=1, le=1_000_000, description="whole sequence periods (or give duration_s)"
    )
    duration_s: Positive | None = Field(None, description="length in seconds (or give periods)")

    @field_validator("seed")
    @classmethod
    def _seed_fits(cls, v: int, info: ValidationInfo) -> int:
        order = info.data.get("order")
        if order is not None and v >= 2**order:
            raise ValueError(
                f"seed must be between 1 and 2**order - 1 = {2**order - 1} (order {order})"
            )
        return v

    @field_validator("transition_s")
    @classmethod
    def _within_chip(cls, v: float, info: ValidationInfo) -> float:
        clock = info.data.get("clock_hz")
        if clock is not None and v > 0.5 / clock:
            raise ValueError(
                f"transition_s is longer than half a chip (0.5 / clock_hz = {0.5 / clock:g} s): "
                "lower clock_hz or transition_s"
            )
        return v

    @model_validator(mode="after")
    def _length(self):
        if (self.periods is None) == (self.duration_s is None):
            raise ValueError("give exactly one of periods or duration_s for a prbs step")
        return self


class MultisineStep(_StepBase):
    """Sum of equal-amplitude cosines with Schroeder phases, scaled to a peak amplitude.

    With the ``K`` frequencies sorted ascending, ``m(t) = sum_k cos(2 pi f_k t + phi_k)``,
    ``phi_k = -pi k (k - 1) / K`` (k = 1..K, Schroeder 1970: a low crest factor), and
    ``V = offset_V + A m(t) / M`` where ``M = max |m|`` over the step's length (on a grid 16
    times finer than the output rate), so ``|V - offset_V|`` peaks at exactly ``A``.
    """

    kind: Literal["multisine"]
    frequencies_hz: list[Positive] = Field(min_length=1, max_length=1000)
    amplitude_V: Positive = Field(description="A: the peak of |V - offset_V|")
    offset_V: Finite = Field(0.0, description="the bias it swings around (0: bipolar)")
    duration_s: Positive = Field(description="length in seconds")

    @field_validator("frequencies_hz")
    @classmethod
    def _distinct(cls, v: list[float]) -> list[float]:
        if len(set(v)) != len(v):
            raise ValueError("frequencies_hz must not repeat a frequency")
        return v


class _StrainStepBase(_StepBase):
    """Keys of the strain-command steps: the command is a strain (ue); the voltage played is
    computed from it by a controller (:mod:`labrig.control`) with fitted model parameters."""

    control: Literal["direct", "compensated"] = Field(
        description="direct: V = S/alpha0; compensated: the inverse model (the paper's Eq. 13)"
    )
    params: FilePath | None = Field(
        None,
        description="model parameters, a JSON file from `labrig fit --out`, relative to this "
        "file (default: the protocol's params)",
    )


class StrainSineStep(_StrainStepBase):
    """Unipolar strain sine ``S = A/2 (1 - cos 2 pi f t)``: 0 ue at t = 0, ``amplitude_ue`` at
    its peaks."""

    kind: Literal["strain_sine"]
    amplitude_ue: Positive = Field(description="peak strain A (the command swings 0..A)")
    frequency_hz: Positive
    cycles: Positive | None = Field(None, description="number of cycles (or give duration_s)")
    duration_s: Positive | None = Field(None, description="length in seconds (or give cycles)")

    @model_validator(mode="after")
    def _length(self):
        _one_of_cycles_duration(self)
        return self


class StrainVanishingStep(_StrainStepBase, _Envelope):
    """Strain sine whose magnitude vanishes (the ``vanishing`` step's envelope, in ue), then
    ``hold_s`` of 0 ue commanded (the controller keeps working: the strain must stay at 0)."""

    kind: Literal["strain_vanishing"]
    amplitude_ue: Positive = Field(description="peak strain at the start of the envelope")
    hold_s: NonNegative = Field(0.0, description="0 ue commanded after the envelope")


class StrainCsvStep(_StrainStepBase):
    """A strain command (ue) read from a CSV file; same file rules as the ``csv`` step."""

    kind: Literal["strain_csv"]
    path: FilePath
    column: ColumnRef | None = Field(
        None, description="strain column: header name or 0-based index (default: first)"
    )
    time_column: ColumnRef | None = Field(None, description="column of sample times (s)")
    rate_hz: Positive | None = Field(None, description="sample rate of the file's rows")
    scale: Finite = Field(1.0, description="multiply the values by this (e.g. 1e6 for strain)")

    @model_validator(mode="after")
    def _timebase(self):
        if self.time_column is not None and self.rate_hz is not None:
            raise ValueError("give time_column or rate_hz for a strain_csv step, not both")
        if self.scale == 0:
            raise ValueError("scale must not be 0")
        return self


Step = Annotated[
    SineStep
    | OffsetSineStep
    | VanishingStep
    | HoldStep
    | RampStep
    | CsvStep
    | SweepStep
    | TriangleStep
    | PrbsStep
    | MultisineStep
    | StrainSineStep
    | StrainVanishingStep
    | StrainCsvStep,
    Field(discriminator="kind"),
]


class Protocol(_Base):
    """A protocol file: a named list of steps played at one sample rate."""

    name: Annotated[str, StringConstraints(min_length=1, max_length=200)]
    description: str | None = None
    rig: Annotated[str, StringConstraints(min_length=1, max_length=4096)] | None = Field(
        None, description="rig file, relative to this file (default: the built-in simulated rig)"
    )
    rate_hz: Positive = Field(description="sample rate for output and acquisition")
    rest_s: NonNegative = Field(0.0, description="default 0 V rest between entries")
    params: FilePath | None = Field(
        None,
        description="default model parameters of the strain-command steps (JSON from "
        "`labrig fit --out`), relative to this file",
    )

    @field_validator("name", "description")
    @classmethod
    def _printable(cls, v: str | None, info: ValidationInfo) -> str | None:
        """No control or format characters (a bell, a right-to-left override): the name is
        printed on terminals and pages, on one line of a listing; a description may hold line
        breaks and tabs."""
        breaks = "\n\t" if info.field_name == "description" else ""
        bad = next((c for c in v or "" if not (c.isprintable() or c in breaks)), None)
        if bad is not None:
            raise ValueError(f"must be printable text (found the control character {bad!r})")
        return v

    metadata: dict[MetaKey, MetaValue] | None = Field(
        None,
        max_length=100,
        description="who ran what on which actuator: operator, sample, actuator_model, "
        "actuator_serial and any other key (text, numbers, true/false); recorded in the run "
        "file (/run/metadata, NXuser, NXsample); --meta KEY=VALUE, --operator and --sample "
        "on the command line win over it",
    )
    edge_slew_V_per_s: Positive = Field(
        1000.0, description="slope of the ramps inserted to start and end every entry at 0 V"
    )
    steps: list[Step] = Field(min_length=1, max_length=10_000)

    @field_validator("metadata")
    @classmethod
    def _storable(cls, values: dict[str, MetaValue] | None) -> dict[str, MetaValue] | None:
        """The rules the run file applies (:func:`labrig.core.metadata.check_value`), so that
        ``labrig check`` refuses what ``labrig run`` could not store."""
        if values is None:
            return None
        try:
            return {k: check_value(k, v) for k, v in values.items()}
        except MetadataError as e:
            raise ValueError(str(e)) from None
