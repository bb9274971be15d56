"""Macro solvers: cantilever and channel, closed forms, exporters for Elmer and Abaqus."""
from homogenize.macro.closed_form import (
    bending_stiffness_N_m2,
    eb_tip_deflection_m,
    elastica_tip_deflection,
    plate_clamped_strip_deflection_m,
    timoshenko_tip_deflection_m,
)

__all__: list[str] = [
    "bending_stiffness_N_m2",
    "eb_tip_deflection_m",
    "elastica_tip_deflection",
    "plate_clamped_strip_deflection_m",
    "timoshenko_tip_deflection_m",
]
