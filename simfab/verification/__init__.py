"""Verification problems with closed-form answers that a user can run to check simfab's mechanics:
:mod:`simfab.verification.cantilever` (a cantilever under a tip load, linear and P2 elements, against
Timoshenko beam theory), :mod:`simfab.verification.hertz` (a rigid sphere pressed into an elastic block,
against Hertz) and
:mod:`simfab.verification.snapfit` (a frictional cantilever snap-fit, against the wedge formula)."""
