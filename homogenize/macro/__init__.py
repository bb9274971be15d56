"""Macro solvers: cantilever and channel, closed forms, exporters for Elmer and Abaqus.

All quantities SI. The strip of :mod:`.cantilever` is clamped at ``x = 0`` with the body force
along ``-z`` (thickness); the channel block of :mod:`.channel` sits on rigid glass at ``z = 0``.
"""
from homogenize.macro.cantilever import MODELS, CantileverResult, Strip, solve_cantilever, \
    tip_deflection_m
from homogenize.macro.channel import ChannelGeometry, ChannelResult, solve_channel
from homogenize.macro.closed_form import (
    bending_stiffness_N_m2,
    eb_tip_deflection_m,
    elastica_tip_deflection,
    plate_clamped_strip_deflection_m,
    timoshenko_tip_deflection_m,
)
from homogenize.macro.exporters import ExportSpec, parse_abaqus, parse_elmer, to_abaqus, \
    to_elmer
from homogenize.macro.fem import Material, linear_solve, neo_hookean_solve

__all__: list[str] = [
    "MODELS", "CantileverResult", "Strip", "solve_cantilever", "tip_deflection_m",
    "ChannelGeometry", "ChannelResult", "solve_channel",
    "bending_stiffness_N_m2", "eb_tip_deflection_m", "elastica_tip_deflection",
    "plate_clamped_strip_deflection_m", "timoshenko_tip_deflection_m",
    "ExportSpec", "parse_abaqus", "parse_elmer", "to_abaqus", "to_elmer",
    "Material", "linear_solve", "neo_hookean_solve",
]
