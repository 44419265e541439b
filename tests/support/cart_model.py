"""The cart of the rest-detection issue's scenarios: an ADXL335 (+-3.6 g, 300 mV/g at 3.3 V, about
150 ug/sqrt(Hz)) on a 10-bit ratiometric ADC at 100 Hz, written as edits of the default model, for the
tests and the bench alike. R = (1.3 mg noise)^2 + (9.8 mg LSB / sqrt(12))^2 = (3.1 mg)^2 = 9.4e-4 (m/s^2)^2."""

from __future__ import annotations

from accelnav.model.load import DEFAULT_MODEL, Model, loads_model

ADXL335_EDITS = [
    ('name = "adxl250_default"', 'name = "adxl335_cart"'),
    ('part = "ADXL250"', 'part = "ADXL335"'),
    ("range_g = 50.0", "range_g = 3.6"),
    ("noise_density_g_rthz = 1.0e-3", "noise_density_g_rthz = 1.5e-4"),
    ("supply_v = 5.0", "supply_v = 3.3"),
    ("adc_bits = 12", "adc_bits = 10"),
    ("adc_ref_v = 5.0", "adc_ref_v = 3.3"),
    ("sensitivity_v_per_g = 0.038", "sensitivity_v_per_g = 0.33"),
    ("zero_g_v = 2.5 ", "zero_g_v = 1.65 "),
    ("zero_g_v = 2.501", "zero_g_v = 1.651"),
    ("R = 0.0160", "R = 9.4e-4"),
]


def adxl335_model(source: str = "adxl335_cart.toml") -> Model:
    """The default model with ADXL335_EDITS, each of which must match exactly once."""
    text = DEFAULT_MODEL.read_text()
    for old, new in ADXL335_EDITS:
        assert text.count(old) == 1, f"the default model's {old!r} line moved"
        text = text.replace(old, new)
    return loads_model(text, source=source)
