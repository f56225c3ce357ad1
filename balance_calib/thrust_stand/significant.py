"""Results written as value ± error, lab manual Supplement 1 §A1.3.

The error keeps 1 or 2 significant digits; the value is rounded to the same decimal place
(half away from zero, 四捨五入), so that no digit below the error's last one is printed.
By default the error keeps 2 digits when its leading digit is 1 or 2 (rounding 0.14 to 0.1
would change it by 30 %) and 1 digit otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass
from decimal import Decimal, ROUND_HALF_UP
import math


@dataclass(frozen=True)
class RoundedResult:
    value: str
    error: str
    # the last printed digit is 10**-decimal_place (negative: tens, hundreds...)
    decimal_place: int

    def __str__(self) -> str:
        return f'{self.value} ± {self.error}'


def _round_to_place(x: float, decimal_place: int) -> Decimal:
    return Decimal(repr(float(x))).quantize(
        Decimal(1).scaleb(-decimal_place), rounding=ROUND_HALF_UP
    )


def _text(rounded: Decimal, decimal_place: int) -> str:
    if decimal_place > 0:
        return f'{rounded:.{decimal_place}f}'
    text = f'{int(rounded):d}'  # 1230, not 1.23E+3
    return '0' if text == '-0' else text


def round_result(
    value: float, error: float, significant_digits: int | None = None
) -> RoundedResult:
    """Round value and error as §A1.3 asks. significant_digits: 1, 2 or None (automatic, above)."""
    if not (math.isfinite(value) and math.isfinite(error)):
        raise ValueError(f'cannot format {value} ± {error}: not finite')
    if error <= 0:
        raise ValueError(f'the error must be positive to set the significant digits, got {error}')
    if significant_digits not in (None, 1, 2):
        raise ValueError('significant_digits must be 1, 2 or None')
    exact_error = Decimal(repr(float(error)))  # decimal digits as printed, no log10 rounding
    exponent = exact_error.adjusted()
    leading_digit = exact_error.as_tuple().digits[0]
    digits = significant_digits or (2 if leading_digit < 3 else 1)
    decimal_place = digits - 1 - exponent
    rounded_error = _round_to_place(error, decimal_place)
    if rounded_error >= Decimal(10) ** (exponent + 1):
        # rounding carried into a new leading digit (0.096 -> 0.10): re-decide with that digit
        exponent += 1
        digits = significant_digits or 2  # the new leading digit is 1
        decimal_place = digits - 1 - exponent
        rounded_error = _round_to_place(error, decimal_place)
    rounded_value = _round_to_place(value, decimal_place)
    value_text = _text(rounded_value, decimal_place)
    if rounded_value.is_zero():
        value_text = value_text.lstrip('-')  # no "-0.00"
    return RoundedResult(value_text, _text(rounded_error, decimal_place), decimal_place)


def format_value_error(
    value: float,
    error: float,
    unit: str = '',
    name: str = '',
    significant_digits: int | None = None,
) -> str:
    """'a = 1.90 ± 0.12 N/mV' style text; `name` and `unit` optional."""
    text = str(round_result(value, error, significant_digits))
    if unit:
        text = f'({text}) {unit}'
    return f'{name} = {text}' if name else text
