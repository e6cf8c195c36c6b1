"""What a deployed predictor carries: Eq. 29 parameters, slider mass and sampling time."""

from __future__ import annotations

from dataclasses import dataclass

from .model import PredictorParams


@dataclass(frozen=True)
class PredictorSetup:
    """What the predictor FMU carries: Eq. 29 parameters, slider mass and the identified sampling time."""

    params: PredictorParams
    slider_mass_kg: float
    T_s: float

    def to_dict(self) -> dict:
        return {"params": self.params.to_dict(), "slider_mass_kg": float(self.slider_mass_kg), "T_s": float(self.T_s)}

    @classmethod
    def from_dict(cls, d: dict) -> "PredictorSetup":
        return cls(PredictorParams.from_dict(d["params"]), float(d["slider_mass_kg"]), float(d["T_s"]))
