"""
``imu-allan plan``: how long must this sensor be recorded.

From a short record (any input ``analyze`` reads: the fit of its minutes) or from a
datasheet's numbers (``--N --B --T_B --K`` with ``--sensor``, or a parameter file
``--params``, both with ``--rate``), print per axis and parameter the expected
relative 95 % half-width now and at 1, 3 and 10 h, and the record length at which it
reaches its target (:mod:`imu_allan.core.plan`; docs/planning.md).
"""

import argparse
import json
from pathlib import Path
import sys

from imu_allan.core.plan.result import more_total
from imu_allan.core.plan.targets import profile_targets, targeted
from imu_allan.errors import InputError

#: Datasheet flags: option -> parameter key of the units module.
_FLAGS = {'N': 'N', 'B': 'B', 'T_B': 'T_B', 'K': 'K'}
#: Each flag's help examples in its customary units: (gyro, accel); test_plan parses them.
_EXAMPLES = {'N': ("'0.15 deg/sqrt(h)'", "'60 ug/sqrt(Hz)'"),
             'B': ("'5 deg/h'", "'40 ug'"),
             'T_B': ("'100 s'",),
             'K': ("'2 deg/h/sqrt(h)'", "'3 ug/sqrt(s)'")}


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register the sub-command."""
    from imu_allan.cli.analyze import add_input_options, add_target_option
    p = subparsers.add_parser(
        'plan', help='how long to record: expected interval widths and time to targets',
        description='Predict from a short record or from datasheet numbers how precise '
                    'each noise parameter will be after 1, 3 and 10 h, and how long a '
                    'record must be for each to reach its target.')
    p.add_argument('input', nargs='?', metavar='INPUT',
                   help='a short record: bag directory, .mcap, .db3, .bag or .csv[.gz]')
    add_input_options(p)
    p.add_argument('--params', type=Path, help='parameter file (YAML, see config/)')
    for flag in _FLAGS:
        given = ' or '.join(_EXAMPLES[flag])
        p.add_argument(f'--{flag}', dest=f'ds_{flag}', metavar='VALUE',
                       help=f'datasheet {flag}, SI or with a unit in quotes '
                            f'(e.g. {given}{"" if flag == "T_B" else " for --sensor accel"})')
    p.add_argument('--sensor', choices=('gyro', 'accel'), default='gyro',
                   help='what the datasheet flags describe (default gyro)')
    add_target_option(p)
    p.add_argument('--format', choices=('text', 'json'), default='text')
    p.set_defaults(run=run)
    return p


def _models_from_numbers(args) -> tuple[dict, float, str]:
    """Per axis the planner's model, the rate and a label, from --params or the flags."""
    from imu_allan.core.noise.params import load_params
    from imu_allan.core.noise.units import to_si
    from imu_allan.core.noise.values import AxisNoise
    from imu_allan.core.plan.planner import noise_components, planning_model

    if not (args.rate and args.rate > 0):
        raise InputError('planning from datasheet numbers needs the sample rate: --rate HZ')
    given = {k: getattr(args, f'ds_{k}') for k in _FLAGS if getattr(args, f'ds_{k}')}
    if args.params is not None:
        if given:
            raise InputError('give either --params or the --N/--B/--T_B/--K flags, not both')
        spec = load_params(args.params)
        axes = spec.axes
        label = f'{args.params} ({spec.name})' if spec.name else str(args.params)
    else:
        if not given:
            raise InputError('nothing to plan from: give INPUT, --params FILE or '
                             '--N/--B/--T_B/--K with --rate')
        values = {k: to_si(v, k, args.sensor) for k, v in given.items()}
        if 'T_B' in values and not values.get('B'):
            raise InputError('--T_B needs --B')
        axes = {args.sensor: AxisNoise(N=values.get('N', 0.0), B=values.get('B', 0.0),
                                       T_B=values.get('T_B'), K=values.get('K', 0.0))}
        label = f'datasheet {args.sensor}'
    models = {a: planning_model(noise_components(n)) for a, n in axes.items()}
    models = {a: m for a, m in models.items() if m[0]}
    if not models:
        raise InputError('the parameters give no noise term to plan with')
    return models, float(args.rate), label


def run(args) -> int:
    """Plan from a record or from numbers; print the tables or one JSON document."""
    targets = profile_targets(args.profile, args.target)
    if args.input is not None:
        if args.params is not None or any(getattr(args, f'ds_{k}') for k in _FLAGS):
            raise InputError('give either INPUT or datasheet numbers, not both')
        from imu_allan.cli.analyze import session_config_from_args
        from imu_allan.io.inputs import analyze_input, check_path
        path = Path(args.input)
        check_path(path)
        result, _ = analyze_input(path, args.topic, session_config_from_args(args),
                                  quiet=args.format == 'json', plan=True, frame_id=args.frame_id,
                                  plan_targets=targets)
        plans, rate, duration = result.plans, result.rate_hz, result.duration_s
        label = str(path)
    else:
        from imu_allan.core.plan.planner import plan_axes
        models, rate, label = _models_from_numbers(args)
        plans, duration = plan_axes(models, rate, 0.0, targets), 0.0
    if args.format == 'json':
        doc = {'source': label, 'rate_hz': rate, 'duration_s': duration,
               'profile': args.profile,
               'targets': {k: (v if v != float('inf') else None) for k, v in targets.items()},
               'axes': {a: p.to_json() for a, p in plans.items()}}
        json.dump(doc, sys.stdout, allow_nan=False)
        sys.stdout.write('\n')
        return 0
    where = (f'a record of {duration / 60.0:.1f} min' if duration > 0
             else 'the given numbers')
    print(f'== {label}: predicted from {where} at {rate:.4g} Hz (relative 95 % half-widths; '
          f'profile {args.profile}: targets on {", ".join(targeted(targets))})')
    for axis, plan in plans.items():
        if duration > 0:
            print(f'{axis}: {plan.progress_line()}')
        else:
            total = max((p.time_s for p in plan.params if p.kind != 'met'), default=0.0)
            print(f'{axis}: every target after {more_total(total, 0.0)}')
        for line in plan.table_lines():
            print(line)
    return 0
