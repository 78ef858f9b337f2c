component pige_true_map_table "pige_sym test: the TRUE tilting table of a trt sim with error maps, and its touch probe";
description """
The true machine of the map loop (tests/linuxcnc/test_linuxcnc_maps.py), written in the test from CONVENTIONS
2, 3 and 10 without pige_sym's code.  Joint 3 is the outer rotary axis (A or B, on the bed), joint 4 the inner
one (C, on the outer axis).  The joint inputs are the MOTOR feedback (the signals J3:pos-fb, J4:pos-fb of the
shipped sims): what the axes' own drives stand at, LinuxCNC's screw compensation included.

Each axis body moves as  x -> q + Rrho R(u', s (theta + E + phi(theta, d))) (x - q) + tau(theta)  (CONVENTIONS 10,
s = -1 on the workpiece side, Rrho the rotation by the small vector rho, exact Rodrigues rotations), with
theta = sense * motor angle, q and u' the axis line (CONVENTIONS 3), E the zero-position error, and the error
maps tau, rho, phi: values at grid angles, linearly interpolated, a full-turn grid wrapping.  phi is given per
direction of approach d: the sign of the axis' last motor motion in theta's sense; 0 (the mean of both) until
the axis first moves, and again after reset-direction.  The inner axis' tau, rho and line are in the outer
axis' body.  The stylus-tip centre is tool_length below joint Z; the probe trips within trip-radius of the
sphere's centre in the table's own coordinates.
""";
pin in float joint_x "joint 0 motor feedback [mm]";
pin in float joint_y "joint 1 motor feedback [mm]";
pin in float joint_z "joint 2 motor feedback [mm]: the spindle's gauge line";
pin in float joint_r1 "joint 3 motor feedback [deg]: outer rotary axis";
pin in float joint_r2 "joint 4 motor feedback [deg]: inner rotary axis";
pin in float sense1 = 1.0;
pin in float sense2 = 1.0;
pin in float r1_px; pin in float r1_py; pin in float r1_pz;
pin in float r1_ux; pin in float r1_uy; pin in float r1_uz;
pin in float r1_zero "zero-position error [rad]";
pin in float r2_px; pin in float r2_py; pin in float r2_pz;
pin in float r2_ux; pin in float r2_uy; pin in float r2_uz = 1.0;
pin in float r2_zero "zero-position error [rad]";
pin in float tool_length "stylus-tip centre below the gauge line [mm]";
pin in float sphere_x; pin in float sphere_y; pin in float sphere_z;
pin in float trip_radius "R + r - pre-travel [mm]";
pin in bit reset_direction "while true: both directions of approach 0 (the state of a fresh start)";
pin out bit probe "tip centre within trip-radius of the sphere centre";
pin out float tip_x "stylus-tip centre in table coordinates [mm]";
pin out float tip_y;
pin out float tip_z;
pin out s32 approach1 "direction of approach of the outer axis, theta sense";
pin out s32 approach2 "direction of approach of the inner axis, theta sense";
pin out float theta1 "the outer axis' true angle [deg]";
pin out float theta2 "the inner axis' true angle [deg]";
pin out s32 trips "rising edges of probe";
pin out float clock "simulated time: the sum of the servo periods since loading [s]";
variable double last1 = 0.0;
variable double last2 = 0.0;
variable int moved = 0;
function _;
license "GPL";
;;
#include <rtapi_math.h>

/* per axis: grid (start, step, nodes, full turn) and per node tau [um] (3), rho [urad] (3, the component along the
   axis unused), phi+ and phi- [urad], in the machine frame of the axis' carrier */
@MAPS@

/* linear interpolation on the grid of axis k at theta [deg] (CONVENTIONS 10) */
static double at(int k, const double *v, double theta)
{
    double u, f;
    int i0, i1, n = NODES[k];
    if (n == 1) return v[0];
    if (FULL[k]) {
        u = fmod(theta - START[k], 360.0);
        if (u < 0.0) u += 360.0;
        u /= STEP[k];
        if (u >= n) u = 0.0;  /* theta a rounding below a full turn: fmod + 360 gives 360 exactly, node 0 again */
        i0 = (int)floor(u);
        i1 = (i0 + 1) % n;
    } else {
        u = (theta - START[k]) / STEP[k];
        if (u <= 0.0) return v[0];
        if (u >= n - 1) return v[n - 1];
        i0 = (int)floor(u);
        i1 = i0 + 1;
    }
    f = u - floor(u);
    return (1.0 - f) * v[i0] + f * v[i1];
}

/* y <- R(w) y: rotation by the vector w [rad] (Rodrigues about w/|w| by |w|) */
static void rotvec(double y[3], const double w[3])
{
    double a = sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]), u[3], c, s, d, x[3];
    int i;
    if (a < 1e-300) return;
    for (i = 0; i < 3; i++) u[i] = w[i] / a;
    c = cos(a);
    s = sin(a);
    d = u[0] * y[0] + u[1] * y[1] + u[2] * y[2];
    x[0] = u[1] * y[2] - u[2] * y[1];
    x[1] = u[2] * y[0] - u[0] * y[2];
    x[2] = u[0] * y[1] - u[1] * y[0];
    for (i = 0; i < 3; i++) y[i] = c * y[i] + s * x[i] + (1.0 - c) * d * u[i];
}

/* y <- M^-1(y) for the body of axis k: x = q + R(u', -s a) Rrho^-1 (y - tau - q), s = -1 (workpiece side) */
static void undo(int k, double y[3], const double q[3], const double u[3], double theta, double zero, int dir)
{
    double v[3], w[3], rho[3], phi;
    int i;
    phi = at(k, dir > 0 ? PHI_PLUS[k] : dir < 0 ? PHI_MINUS[k] : PHI_MEAN[k], theta);
    for (i = 0; i < 3; i++) {
        v[i] = y[i] - at(k, TAU[k][i], theta) * 1e-3 - q[i];
        rho[i] = -at(k, RHO[k][i], theta) * 1e-6;
    }
    rotvec(v, rho);
    /* the body turned by s * (theta + E + phi) = -(...): undo it by turning +(...) */
    for (i = 0; i < 3; i++) w[i] = u[i] * (theta * M_PI / 180.0 + zero + phi * 1e-6);
    rotvec(v, w);
    for (i = 0; i < 3; i++) y[i] = q[i] + v[i];
}

FUNCTION(_) {
    double y[3] = {joint_x, joint_y, joint_z - tool_length};
    double q1[3] = {r1_px, r1_py, r1_pz}, u1[3] = {r1_ux, r1_uy, r1_uz};
    double q2[3] = {r2_px, r2_py, r2_pz}, u2[3] = {r2_ux, r2_uy, r2_uz};
    double t1 = sense1 * joint_r1, t2 = sense2 * joint_r2, dx, dy, dz, g;
    int was = probe;
    clock = clock + fperiod;
    if (moved) {
        if (joint_r1 != last1) approach1 = (sense1 * (joint_r1 - last1)) > 0 ? 1 : -1;
        if (joint_r2 != last2) approach2 = (sense2 * (joint_r2 - last2)) > 0 ? 1 : -1;
    }
    moved = 1;
    last1 = joint_r1;
    last2 = joint_r2;
    if (reset_direction) {
        approach1 = 0;
        approach2 = 0;
    }
    theta1 = t1;
    theta2 = t2;
    undo(0, y, q1, u1, t1, r1_zero, approach1);  /* the outer axis first, then the inner one in its body */
    undo(1, y, q2, u2, t2, r2_zero, approach2);
    tip_x = y[0]; tip_y = y[1]; tip_z = y[2];
    dx = y[0] - sphere_x; dy = y[1] - sphere_y; dz = y[2] - sphere_z;
    g = sqrt(dx * dx + dy * dy + dz * dz) - trip_radius;
    probe = g <= 0.0;
    if (probe && !was) trips = trips + 1;
}
