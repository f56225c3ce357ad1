"""The one order a calibration runs in, whatever its points were read from.

calibrate/path.calibrate runs `run_stages` on a bag's points (refit/pipeline.BagStages) and on
a table's (tables/calibrate.TableStages):

1. screen: the gates on the points as read, judged before any fit (a bag's output range, a
   table's channels): a unit error is named before it spoils every fit;
2. fit: model selection and the least-squares fits (a bag's linear, quadratic and cubic models
   of TM-663 §2-3 after the body tare §6-7; a table's model forms and term sets with series
   tares);
3. data gates: what no effect found later can change (a bag's sensitivity, capacity, body
   weight, zero points and schedule; a table's sensitivity), judged before the diagnosis spends
   its time;
4. diagnose: the residuals examined for effects the model lacks, on what the points carry;
5. fit gates: σ, outliers, overfit and condition of the model that will be adopted, judged
   after the diagnosis (a point whose disagreement an adopted or named effect explains is no
   weight error);
6. result: the calibration and its report, the gates and whether they were forced.

A failed gate stops the calibration at its stage with one line naming the most specific cause
(`gates.gate.refusal`), unless forced; then the report says so. This module sits beside
calibration_points.py and calibration_settings.py so that both sides (refit/, tables/) and the
calibrate/ package above them can use it without an import cycle.
"""

from __future__ import annotations

from typing import Callable, Protocol, Sequence, TypeVar

from .gates.gate import Gate, refusal

Result = TypeVar('Result', covariant=True)
Progress = Callable[[str], None]


class Stages(Protocol[Result]):
    """One side's steps, in the order run_stages calls them (the module's docstring)."""

    @property
    def where(self) -> str:
        """The source named in front of a refusal (the bags' files, the table's file)."""
        ...

    @property
    def priority(self) -> Sequence[str]:
        """Gate names, most specific cause first: the order a refusal names failures in."""
        ...

    @property
    def names_others(self) -> bool:
        """Whether a refusal also lists the stage's other failed gates."""
        ...

    def refused(self, message: str) -> Exception:
        """The side's error for a refusal (RefitError, TableCalibrationError)."""
        ...

    def screen(self) -> list[Gate]: ...

    def fit(self) -> None: ...

    def data_gates(self) -> list[Gate]: ...

    def diagnose(self) -> None: ...

    def fit_gates(self) -> list[Gate]: ...

    def result(self, gates: Sequence[Gate], forced: bool) -> Result: ...


def run_stages(stages: Stages[Result], force: bool, progress: Progress | None = None) -> Result:
    """The calibration `stages` produce, run in the one order; raises the side's error at the
    first stage whose gates fail, unless `force`.
    """
    say = progress or (lambda message: None)
    gates = _judged(stages.screen(), stages, force, say)
    stages.fit()
    gates += _judged(stages.data_gates(), stages, force, say)
    stages.diagnose()
    gates += _judged(stages.fit_gates(), stages, force, say)
    return stages.result(gates, force)


def _judged(gates: list[Gate], stages: Stages, force: bool, say: Progress) -> list[Gate]:
    """`gates`, each said; the side's error for the first failure unless `force`."""
    for gate in gates:
        say(f'gate {gate.name}: {"ok" if gate.passed else "FAILED"}: {gate.reason}')
    message = refusal(stages.where, gates, stages.priority, stages.names_others)
    if message is not None and not force:
        raise stages.refused(message)
    return gates
