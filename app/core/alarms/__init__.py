"""Alarms on the displayed angles: limits with hysteresis and a delay (no Qt).

(The package: :mod:`.limits` what an alarm is and its text form, :mod:`.monitor` the
crossings, :mod:`.recording` the ``alarm_events`` of a recording.)

An :class:`AlarmLimit` watches one quantity of the filtered angles, in degrees:

- ``roll``, ``pitch``: may have a ``lower`` and an ``upper`` limit (e.g. -2 and +2);
- ``tilt``: the total tilt from vertical (never negative), lower and/or upper limit;
- ``level``: "out of level", the tilt beyond a tolerance (``upper`` only).

It **raises** once the value has been beyond a limit (``> upper`` or ``< lower``) for
``delay_s`` without a break, and **clears** once the value has been back inside by at least the
hysteresis (``<= upper - hysteresis`` and ``>= lower + hysteresis``) for the same ``delay_s``.
Clearing waits as raising does so that a value hovering at the limit gives neither a flicker of
alarm nor a flicker of all-clear. Time is the device clock of the samples, so a replay run
faster than real time raises at the same moments as live. A sample that is not a number
(NaN) neither raises nor clears and breaks a run.

The :class:`AlarmMonitor` runs the enabled limits over each block of angles (the pipeline's
orientation output, after any tare: what the instrument shows) and returns the crossings as
:class:`AlarmEvent` objects, which recordings store under the ``alarm_events`` metadata key
(docs/recording-format.md) and ``record --alarm`` prints.

The text form (``record --alarm``)::

    tilt>2.0,hyst=0.2,delay=0.5     tilt above 2 degrees
    roll<-1.5                       roll below -1.5 degrees
    |pitch|>1                       pitch above +1 or below -1 degrees
    roll>2,roll<-1                  both limits on roll
    level>0.5                       out of level: tilt beyond 0.5 degrees
    heading:350..10                 magnetic heading outside the sector 350 to 10 (clockwise)
    |heading-45|>5                  magnetic heading more than 5 degrees off 45, either way
    heading-45>5                    more than 5 degrees clockwise of 45 (<-5: anticlockwise)

A heading alarm watches the pipeline's ``heading`` column (the magnetic heading of +x, NaN
without a 9-axis filter taking it from a field, or near vertical: no raise, no clear) as its
difference from the set heading, wrapped into -180 ... 180 degrees, so a sector across north
works.

Options: ``hyst`` (degrees, default 0.1) and ``delay`` (seconds, default 0.5).
"""

from app.core.alarms.limits import (
    DEFAULT_DELAY_S,
    DEFAULT_HYSTERESIS_DEG,
    MAX_DELAY_S,
    QUANTITIES,
    QUANTITY_TITLES,
    READOUT_OF,
    AlarmConfig,
    AlarmLimit,
    alarms_from_specs,
    default_alarm_config,
    parse_alarm,
)
from app.core.alarms.monitor import CLEARED, RAISED, AlarmEvent, AlarmMonitor
from app.core.alarms.recording import (
    KEY_ALARM_EVENTS,
    KEY_ALARMS,
    alarm_events_metadata,
    recorded_alarm_events,
    save_alarm_events,
)

__all__ = [
    "CLEARED", "DEFAULT_DELAY_S", "DEFAULT_HYSTERESIS_DEG", "KEY_ALARMS", "KEY_ALARM_EVENTS",
    "MAX_DELAY_S", "QUANTITIES", "QUANTITY_TITLES", "RAISED", "READOUT_OF", "AlarmConfig",
    "AlarmEvent", "AlarmLimit", "AlarmMonitor", "alarm_events_metadata", "alarms_from_specs",
    "default_alarm_config", "parse_alarm", "recorded_alarm_events", "save_alarm_events",
]
