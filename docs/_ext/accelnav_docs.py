"""Sphinx directives that generate reference pages from the code itself, so the pages cannot drift.

``.. accelnav-model-keys::`` tabulates every key of the model file. The rows are not typed here: the
loader is run on every shipped model with its ``_Table`` swapped for a recorder, so each key, its type,
default, bounds and choices are what the loader's own calls validate. Only the one-line meaning of each
key is written here (KEY_MEANINGS); a key the loader reads without a meaning, or a meaning for a key it
no longer reads, is a warning (an error under ``-W``).

``.. accelnav-command:: NAME`` renders the options of one subcommand from its argparse parser.
"""

from __future__ import annotations

import argparse
import contextlib
import re
from dataclasses import dataclass, field
from pathlib import Path

from docutils import nodes
from docutils.parsers.rst import directives
from docutils.statemachine import StringList
from sphinx.util import logging
from sphinx.util.docutils import SphinxDirective
from sphinx.util.nodes import nested_parse_with_titles

log = logging.getLogger(__name__)

# The meaning of each key, one line; everything else in the table comes from the loader.
KEY_MEANINGS = {
    "model": "Name and description of the model.",
    "model.name": "Model name: shown in generated C banners, reports and manifests.",
    "model.description": "Free text describing the sensor set-up.",
    "sensor": "The sensor part and how it is read out.",
    "sensor.kind": "How samples arrive: an ADC read-out, a duty-cycle timer capture, or already acceleration.",
    "sensor.part": "Part name, for people (not checked further).",
    "sensor.range_g": "Full scale, +-g; a sample at it is taken as clipped.",
    "sensor.noise_density_g_rthz": "Datasheet noise density, g/sqrt(Hz) (the simulator's noise).",
    "sensor.bandwidth_hz": "-3 dB bandwidth of the output filter, Hz.",
    "sensor.analog": "ADC read-out of an analog output (kind = 'analog').",
    "sensor.analog.supply_v": "Sensor supply, V.",
    "sensor.analog.adc_bits": "ADC resolution, bits.",
    "sensor.analog.adc_ref_v": "ADC reference, V; equal to supply_v when ratiometric.",
    "sensor.analog.sensitivity_v_per_g": "Sensitivity, V/g.",
    "sensor.analog.zero_g_v": "Output at 0 g, V; below adc_ref_v.",
    "sensor.duty_cycle": "Timer capture of a duty-cycle output (kind = 'duty_cycle').",
    "sensor.duty_cycle.timer_clock_hz": "Capture timer clock, Hz.",
    "sensor.duty_cycle.t2_period_s": "Duty-cycle period T2, s; at most one sample period, at least 16 timer counts.",
    "sensor.duty_cycle.zero_g_duty": "Duty cycle T1/T2 at 0 g.",
    "sensor.duty_cycle.duty_per_g": "Duty-cycle change per g.",
    "sensor.calibrated": "Samples already in g or m/s^2 (kind = 'calibrated'; host tools only, codegen refuses it).",
    "sensor.calibrated.unit": "Unit of the samples.",
    "sensor.calibrated.lsb_per_g": "Counts per g of a digital part (the simulator quantises with it; 0: not given).",
    "sampling": "Sampling.",
    "sampling.rate_hz": "Sample rate, Hz; a recording must match it within 1 %.",
    "axes": "One [[axes]] table per sensing axis, 1 to 3 of them.",
    "axes[].name": "Axis name; distinct from the others ignoring case, none another's name followed by _.",
    "axes[].c1": "Bias model eps(t) = c1 (1 - exp(-t/T)) + c2: the warm-up part, m/s^2.",
    "axes[].c2": "Bias model: the constant part, m/s^2; abs(c1) + abs(c2) within the full scale.",
    "axes[].T": "Bias model: the warm-up time constant, s.",
    "axes[].sensitivity_v_per_g": "This axis's own sensitivity, V/g (analog), from its calibration.",
    "axes[].zero_g_v": "This axis's 0 g output, V (analog).",
    "axes[].duty_per_g": "This axis's duty-cycle change per g (duty_cycle).",
    "axes[].zero_g_duty": "This axis's duty cycle at 0 g (duty_cycle).",
    "noise": "Noise figures of the filter.",
    "noise.sigma_n": "White-jerk intensity driving the acceleration, m/s^2/sqrt(s).",
    "noise.sigma_eps": "Random-walk intensity of the bias, m/s^2/sqrt(s).",
    "noise.R": "Variance of one acceleration sample, (m/s^2)^2.",
    "ranges": "Declared ranges: every fixed-point format of the generated C is chosen for them.",
    "ranges.max_velocity_m_s": "Largest speed abs(u), m/s.",
    "ranges.max_position_m": "Largest distance abs(r) from the start, m.",
    "ranges.max_run_s": "Longest run the generated C's range proof covers, s (host tools take longer runs).",
    "filter": "Filter options.",
    "filter.form": "Form of the generated filter: the covariance block, or a table of gains.",
    "filter.initial_sigma": "One-sigma uncertainty of the initial state [r, u, a, eps], an array of 4 numbers >= 0.",
}

# Defaults the loader computes from other keys, and tables required for one sensor kind only: the
# recorder sees what one model gave, not the rule.
COMPUTED_DEFAULTS = {
    "sensor.analog": "required when kind = 'analog'",
    "sensor.duty_cycle": "required when kind = 'duty_cycle'",
    "sensor.calibrated": "required when kind = 'calibrated'",
    "sensor.analog.adc_ref_v": "supply_v",
    "sensor.analog.zero_g_v": "supply_v / 2",
    "axes[].sensitivity_v_per_g": "sensor.analog's",
    "axes[].zero_g_v": "sensor.analog's",
    "axes[].duty_per_g": "sensor.duty_cycle's",
    "axes[].zero_g_duty": "sensor.duty_cycle's",
}


@dataclass
class KeyInfo:
    """What the loader's calls say about one key (merged over every shipped model)."""

    key: str
    kind: str  # number, integer, string, table, array
    required: bool = True
    defaults: set = field(default_factory=set)
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    choices: tuple[str, ...] | None = None
    name_rule: str | None = None  # what the one name rule accepts, for names that reach C


def _norm(path: str) -> str:
    return re.sub(r"\[\d+\]", "[]", path)


def model_keys() -> list[KeyInfo]:
    """Every key the loader validates, in the order it reads them, from loading each shipped model."""
    from accelnav.model import load
    from accelnav.resources import models_dir

    keys: dict[str, KeyInfo] = {}
    kinds_seen: set[str] = set()

    def note(key: str, kind: str, default=..., **rules) -> KeyInfo:
        info = keys.setdefault(key, KeyInfo(key, kind))
        if default is not ...:
            info.required = False
            info.defaults.add(repr(default))
        for name, value in rules.items():
            if value is not None:
                setattr(info, name, value)
        return info

    class Recorder(load._Table):
        def table(self, name, required=True):
            note(_norm(self.key(name)), "table", ... if required else None)
            return super().table(name, required)

        def raw(self, name, default=...):
            if _norm(self.key(name)) not in keys:  # a raw read outside number/integer/string: an array
                note(_norm(self.key(name)), "array", default)
            return super().raw(name, default)

        def number(self, name, default=..., *, lo=None, hi=None, lo_open=False):
            note(_norm(self.key(name)), "number", default, lo=lo, hi=hi, lo_open=lo_open or None)
            return super().number(name, default, lo=lo, hi=hi, lo_open=lo_open)

        def integer(self, name, default=..., *, lo, hi):
            note(_norm(self.key(name)), "integer", default, lo=lo, hi=hi)
            return super().integer(name, default, lo=lo, hi=hi)

        def string(self, name, default=..., *, choices=None):
            note(_norm(self.key(name)), "string", default, choices=choices)
            return super().string(name, default, choices=choices)

    check_name = load._check_name

    def recording_check_name(t, key, value, kind):
        keys[_norm(t.key(key))].name_rule = load._NAME_RULES[kind][1]
        return check_name(t, key, value, kind)

    models = sorted(Path(models_dir()).glob("*.toml"))
    # an empty parsed-model cache: a model this process loaded before would come back without being read
    with _swapped(load, _Table=Recorder, _check_name=recording_check_name, _PARSED={}):
        for path in models:
            model = load.load_model(path)
            kinds_seen.add(model.sensor.kind)
    keys["axes"] = KeyInfo("axes", "array of tables")
    missing = set(load.SENSOR_KINDS) - kinds_seen
    if missing:  # a branch of the loader no shipped model walks would leave its keys out
        raise RuntimeError(f"no shipped model has sensor.kind {sorted(missing)}: the key reference would miss keys")
    return list(keys.values())


@contextlib.contextmanager
def _swapped(module, **names):
    old = {k: getattr(module, k) for k in names}
    try:
        for k, v in names.items():
            setattr(module, k, v)
        yield
    finally:
        for k, v in old.items():
            setattr(module, k, v)


def _accepted(info: KeyInfo) -> str:
    if info.choices:
        return ", ".join(f"``{c!r}``" for c in info.choices)
    if info.name_rule:
        return info.name_rule.replace("*", r"\*")
    if info.kind in ("number", "integer") and (info.lo is not None or info.hi is not None):
        left = "(" if info.lo_open and info.kind == "number" else "["
        lo = "-inf" if info.lo is None else f"{info.lo:g}"
        hi = "inf" if info.hi is None else f"{info.hi:g}"
        return f"{left}{lo}, {hi}]"
    return ""


def _default(info: KeyInfo) -> str:
    if info.key in COMPUTED_DEFAULTS:
        return COMPUTED_DEFAULTS[info.key]
    if info.required:
        return "required"
    values = sorted(info.defaults - {"None"})
    return ", ".join(f"``{v}``" for v in values) if values else "optional"


def model_key_rows() -> list[tuple[str, ...]]:
    """(key, type, default, accepted, meaning) per key; warns of keys and meanings that do not match."""
    keys = model_keys()
    read = {k.key for k in keys}
    for key in sorted(read - set(KEY_MEANINGS)):
        log.warning(f"accelnav-model-keys: the loader reads {key!r}, which has no meaning in KEY_MEANINGS")
    for key in sorted(set(KEY_MEANINGS) - read):
        log.warning(f"accelnav-model-keys: KEY_MEANINGS has {key!r}, which the loader does not read")
    for info in keys:
        if info.key not in COMPUTED_DEFAULTS and len(info.defaults - {"None"}) > 1:
            log.warning(
                f"accelnav-model-keys: {info.key!r} has differing defaults {info.defaults}: the loader computes it, "
                "say how in COMPUTED_DEFAULTS"
            )
    order = {k: i for i, k in enumerate(KEY_MEANINGS)}
    keys.sort(key=lambda k: order.get(k.key, len(order)))
    return [(f"``{k.key}``", k.kind, _default(k), _accepted(k), KEY_MEANINGS.get(k.key, "")) for k in keys]


class ModelKeys(SphinxDirective):
    def run(self):
        lines = [".. list-table::", "   :header-rows: 1", "   :widths: 22 8 12 20 38", ""]
        for row in [("Key", "Type", "Default", "Accepted", "Meaning"), *model_key_rows()]:
            lines.append(f"   * - {row[0]}")
            lines += [f"     - {cell}" for cell in row[1:]]
        node = nodes.container()
        nested_parse_with_titles(self.state, StringList(lines, source="accelnav-model-keys"), node)
        return node.children


def _subparser(name: str) -> argparse.ArgumentParser:
    from accelnav.cli import build_parser

    parser = build_parser()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            path = name.split()
            if not path:
                return parser
            sub = action.choices[path[0]]
            for part in path[1:]:  # e.g. "log info"
                sub = next(a for a in sub._actions if isinstance(a, argparse._SubParsersAction)).choices[part]
            return sub
    raise KeyError(name)


def command_summary(name: str) -> str:
    """The one line ``accelnav --help`` (or ``accelnav log --help``) gives subcommand ``name``."""
    from accelnav.cli import build_parser

    *parents, last = name.split()
    parser = _subparser(" ".join(parents)) if parents else build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return next((c.help or "") for c in action._choices_actions if c.dest == last)


def command_options(name: str) -> tuple[str, list[tuple[str, str]]]:
    """(usage, [(invocation, help)]) of subcommand ``name``, as argparse formats them."""
    parser = _subparser(name)
    formatter = parser._get_formatter()
    rows = []
    for action in parser._actions:
        if action.help == argparse.SUPPRESS or isinstance(action, argparse._SubParsersAction):
            continue
        text = formatter._expand_help(action) if action.help else ""  # %(default)s and the like filled in
        rows.append((formatter._format_action_invocation(action), text))
    return parser.format_usage().strip(), rows


class CommandOptions(SphinxDirective):
    required_arguments = 1
    final_argument_whitespace = True
    option_spec = {"no-usage": directives.flag}

    def run(self):
        name = self.arguments[0]
        documented = self.env.__dict__.setdefault("accelnav_commands", set())
        documented.add(name)
        usage, rows = command_options(name)
        summary = command_summary(name)
        description = _subparser(name).description
        out = [nodes.paragraph(summary, summary[:1].upper() + summary[1:] + ".")]
        if description:
            out.append(nodes.paragraph(description, description))
        if "no-usage" not in self.options:
            out.append(nodes.literal_block(usage, usage))
        dl = nodes.definition_list()
        for invocation, text in rows:  # plain text nodes: help strings are not parsed as markup
            item = nodes.definition_list_item()
            item += nodes.term("", "", nodes.literal(invocation, invocation))
            item += nodes.definition("", nodes.paragraph(text, text))
            dl += item
        out.append(dl)
        return out


def plain_docstrings(app, what, name, obj, options, lines) -> None:
    """The package's docstrings are plain text for ``help()``, not reStructuredText: |a| is an absolute
    value, not a substitution, and a module's notes are laid out with indentation and underlines. So the
    bars are escaped, and a module's docstring after its summary line is shown as written (preformatted)."""
    if what == "module":
        blank = lines.index("") if "" in lines else len(lines)
        body = lines[blank:]
        lines[blank:] = ["", "::", ""] + ["    " + line for line in body] if any(body) else []
        lines[:blank] = [line.replace("|", r"\|") for line in lines[:blank]]
        return
    lines[:] = [line.replace("|", r"\|") for line in lines]


def command_names() -> list[str]:
    """The subcommands ``accelnav --help`` lists."""
    parser = _subparser("")
    return list(next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices)


def _merge_commands(app, env, docnames, other) -> None:
    env.__dict__.setdefault("accelnav_commands", set()).update(getattr(other, "accelnav_commands", set()))


def _check_commands(app, env) -> None:
    """Every subcommand has a page: a command added to the CLI without one is a warning."""
    documented = getattr(env, "accelnav_commands", set())
    for name in command_names():
        if name not in documented:
            log.warning(f"accelnav-command: subcommand {name!r} has no page (no '.. accelnav-command:: {name}')")


def setup(app):
    app.connect("autodoc-process-docstring", plain_docstrings)
    app.connect("env-merge-info", _merge_commands)
    app.connect("env-check-consistency", _check_commands)
    app.add_directive("accelnav-model-keys", ModelKeys)
    app.add_directive("accelnav-command", CommandOptions)
    return {"parallel_read_safe": True, "version": "1"}
