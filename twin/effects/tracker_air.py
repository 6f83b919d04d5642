"""The tracker's air compensation set for another temperature than the hall's.

The tracker divides the optical path it measures by the refractive index of the air it
believes the beam crosses; if it believes ``set_C`` while the hall is at ``hall_C`` every
distance from the head is off by n(hall) / n(set) - 1, about -0.93 ppm per kelvin (modified
Edlen equation, :func:`twin.tracker.air_refractive_index`). Default: a tracker left at 20 C in
a 23 C hall, -2.8 ppm, 11 um at 4 m. The physics is :class:`twin.tracker.AirCompensation`;
this effect puts it on the tracker of a measurement so a scenario switches it on by name.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from twin.tracker import AirCompensation, Tracker


@dataclass(frozen=True)
class TrackerAirTemperature:
    hall_C: float = 23.0  # the air the beam crosses
    set_C: float = 20.0  # the air the tracker compensates for
    pressure_Pa: float = 101325.0
    water_vapour_Pa: float = 1170.0  # 50 % humidity at 20 C
    wavelength_m: float = 633e-9
    name: str = "tracker_air_temperature"

    def __post_init__(self) -> None:
        self.air()  # validates

    def air(self) -> AirCompensation:
        return AirCompensation(
            self.hall_C, self.set_C, self.pressure_Pa, self.water_vapour_Pa, self.wavelength_m
        )

    def on_tracker(self, tracker: Tracker) -> Tracker:
        if tracker.air is not None:
            raise ValueError(
                "the tracker already has an air compensation model; give it once, as the "
                "tracker's 'air' or as the 'tracker_air_temperature' effect"
            )
        return dataclasses.replace(tracker, air=self.air())
