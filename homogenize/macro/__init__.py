"""Macro solvers: cantilever and channel (with flow), closed forms, real magnets, the effective
material fed by batch tables, element studies, exporters and complete decks for CalculiX/Abaqus
and Elmer.

All quantities SI. The strip of :mod:`.cantilever` is clamped at ``x = 0`` with the body force
along ``-z`` (thickness); the channel block of :mod:`.channel` sits on rigid glass at ``z = 0``.
"""
from homogenize.macro.cantilever import MODELS, CantileverResult, Strip, solve_cantilever, \
    tip_deflection_m
from homogenize.macro.channel import ChannelGeometry, ChannelResult, solve_channel
from homogenize.macro.closed_form import (
    BodyForceProfile,
    bending_stiffness_N_m2,
    eb_tip_deflection_m,
    elastica_tip_deflection,
    plate_clamped_strip_deflection_m,
    timoshenko_tip_deflection_m,
)
from homogenize.macro.convergence import ConvergedTip, converged_tip
from homogenize.macro.effective import (EffectiveMaterial, beam_with_interval,
                                        effective_material_from_table,
                                        magnetization_from_table, tip_deflection_from_table)
from homogenize.macro.exporters import ExportSpec, parse_abaqus, parse_elmer, to_abaqus, \
    to_elmer, write_deck
from homogenize.macro.fem import Material, linear_solve, neo_hookean_solve
from homogenize.macro.flow import (BLOOD_PLASMA, CeilingModel, Liquid, field_for_target_gap,
                                   solve_channel_flow)
from homogenize.macro.magnets import Coil, PermanentMagnet, body_force_along_strip, sample_field

__all__: list[str] = [
    "MODELS", "CantileverResult", "Strip", "solve_cantilever", "tip_deflection_m",
    "ChannelGeometry", "ChannelResult", "solve_channel",
    "BodyForceProfile", "bending_stiffness_N_m2", "eb_tip_deflection_m",
    "elastica_tip_deflection", "plate_clamped_strip_deflection_m", "timoshenko_tip_deflection_m",
    "ConvergedTip", "converged_tip",
    "EffectiveMaterial", "beam_with_interval", "effective_material_from_table",
    "magnetization_from_table", "tip_deflection_from_table",
    "ExportSpec", "parse_abaqus", "parse_elmer", "to_abaqus", "to_elmer", "write_deck",
    "Material", "linear_solve", "neo_hookean_solve",
    "BLOOD_PLASMA", "CeilingModel", "Liquid", "field_for_target_gap", "solve_channel_flow",
    "Coil", "PermanentMagnet", "body_force_along_strip", "sample_field",
]
