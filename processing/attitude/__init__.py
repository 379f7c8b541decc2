"""Attitude core: quaternion/DCM/MRP/Euler algebra (``rotations``), MRP kinematics (``mrp_kinematics``),
Wahba's problem by q-method, QUEST and SVD (``wahba``, paper 002 eq. 8-9) and rigid-body dynamics
with gravity-gradient torque (``rigid_body``, paper 004 eq. 1-2).
"""
