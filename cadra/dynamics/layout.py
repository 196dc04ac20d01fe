"""Plain-array layouts shared by the simulator and the fitter (one home for the indices).

State vector (13 entries, SI):

=====  ==========================================================
index  meaning
=====  ==========================================================
0-2    cg position in the facility frame F, m
3-5    cg velocity in F, m/s (inertial; the air may move, see ``P_WIND``)
6-9    attitude quaternion (w, x, y, z), body B -> earth-aero E
10-12  body rates (p, q, r) about x_b, y_b, z_b, rad/s
=====  ==========================================================

Physical-constants vector ``phys`` (same dtype as the state, so complex-step derivatives can be
taken with respect to any entry, effects included):

=======  ===================================================================================
index    meaning
=======  ===================================================================================
0        mass, kg
1-9      inertia tensor about the cg in body axes, row-major, kg m^2
10       reference length d, m
11       reference area S = pi d^2 / 4, m^2
12       air density at x = 0, kg/m^3
13       speed of sound, m/s
14       dynamic viscosity, Pa s (for the Reynolds number variable)
15       gravity g, m/s^2 (acts along -z_F)
16-18    uniform air velocity (wind, cross-flow) in F, m/s                    [effect]
19-21    d(wind)/dx along the range, 1/s                                     [effect]
22       relative density gradient along the range (1/rho) d rho/dx, 1/m     [effect]
23-25    cg offset from the aerodynamic moment reference point, body axes, m [effect]
26       test mode code (``MODE_*`` below; :mod:`cadra.dynamics.modes`)
27-29    pivot (gimbal centre, pivot or bearing axis point) minus the nominal cg, body axes, m
30       attitude frame code (``FRAME_*`` below): what the quaternion and the rates' axes are
=======  ===================================================================================

The aerodynamic model's moment coefficients are about the moment reference point, which is the
nominal cg of the shot file; a non-zero cg offset (the "lateral cg offset" effect) moves the true
cg away from it and adds ``-offset x F`` to the moment about the cg.

The attitude frame (docs/dynamics.md, "The non-rolling frame"): with ``FRAME_BODY`` the
quaternion is the body's own and (p, q, r) are about its axes. With ``FRAME_NONROLLING`` (a
body of revolution whose physics does not depend on its roll angle) the quaternion is that of a
frame whose x axis is the body's axis but which does not roll with it: it turns at (0, q, r),
and (p, q, r) are the body's rates along that frame's axes. The body's spin p then sets no step.
"""

from __future__ import annotations

N_STATE = 13
S_POS = slice(0, 3)
S_VEL = slice(3, 6)
S_QUAT = slice(6, 10)
S_RATES = slice(10, 13)

P_MASS = 0
P_INERTIA = 1
P_D = 10
P_S = 11
P_RHO = 12
P_SOUND = 13
P_MU = 14
P_G = 15
P_WIND = 16
P_WIND_GRAD = 19
P_RHO_GRAD = 22
P_CG_OFFSET = 23
P_MODE = 26
P_PIVOT = 27
P_FRAME = 30
N_PHYS = 31

#: angle-plane codes of an aerodynamic model (see docs/conventions.md)
PLANE_ALPHA_BETA = 0
PLANE_SIGMA = 1

#: test-mode codes (docs/dynamics.md, "Test modes"): free flight (a range, or a wind tunnel's
#: stream), a 3-DOF angular gimbal about a fixed point, a 1-DOF pitch pivot about body y, a
#: 1-DOF roll bearing about body x
MODE_FREE = 0
MODE_GIMBAL = 1
MODE_PITCH = 2
MODE_ROLL = 3

#: attitude-frame codes (``phys[P_FRAME]``): the body's own axes, or the non-rolling frame
FRAME_BODY = 0
FRAME_NONROLLING = 1
