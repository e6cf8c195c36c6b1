"""What a deployed predictor carries: Eq. 29 parameters, slider mass, sampling time and the frequency response."""

from __future__ import annotations

from dataclasses import dataclass

from .frequency import FrequencyResponse
from .model import PredictorParams


@dataclass(frozen=True)
class PredictorSetup:
    """What the predictor FMU carries: Eq. 29 parameters, slider mass, the identified sampling time, and the
    drive-frequency response of the force factor (None: gain 1 at every frequency)."""

    params: PredictorParams
    slider_mass_kg: float
    T_s: float
    frequency: FrequencyResponse | None = None

    def to_dict(self) -> dict:
        d = {"params": self.params.to_dict(), "slider_mass_kg": float(self.slider_mass_kg), "T_s": float(self.T_s)}
        if self.frequency is not None:
            d["frequency"] = self.frequency.to_dict()
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "PredictorSetup":
        return cls(PredictorParams.from_dict(d["params"]), float(d["slider_mass_kg"]), float(d["T_s"]),
                   FrequencyResponse.from_dict(d.get("frequency")))

    @property
    def f_nominal_Hz(self) -> float:
        """The drive frequency at which the gain is 1 [Hz] (48.5 kHz, the paper's, without a response)."""
        return 48500.0 if self.frequency is None else self.frequency.f_ref_Hz
