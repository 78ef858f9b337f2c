component pige_true_table "pige_sym test: the TRUE tilting table of a simulated trt machine and its touch probe";
description """
The true machine of tests/linuxcnc.  From the joint feedback it computes where the stylus-tip centre is in
the table's own coordinates and trips the probe when that point is within trip-radius of the calibration
sphere's centre.  Joint 3 is the outer rotary axis (A or B, on the bed), joint 4 the inner one (C).

Two models of the same table run side by side:
the machine's kinematics emitted by pige (pige_sym.codegen.c_model.render_model_c, inlined below:
nominal pivots, senses and the PIGEs as errors[], forward kinematics joints -> tool point) drive
the probe and the tip pins; the twin, written in the test from CONVENTIONS §2-3 (each axis line a point and a
unit direction, exact Rodrigues rotations, the carried body turned by -(sense * joint + zero)), gives the
same point independently, and twin-diff holds the largest distance between the two seen since loading.
""";
pin in float joint_x "joint 0 feedback [mm]";
pin in float joint_y "joint 1 feedback [mm]";
pin in float joint_z "joint 2 feedback [mm]: the spindle's gauge line";
pin in float joint_r1 "joint 3 feedback [deg]: outer rotary axis";
pin in float joint_r2 "joint 4 feedback [deg]: inner rotary axis";
pin in float pivot1_x; pin in float pivot1_y; pin in float pivot1_z;
pin in float pivot2_x; pin in float pivot2_y; pin in float pivot2_z;
pin in float sense1 = 1.0;
pin in float sense2 = 1.0;
pin in float err_#[@N_ERRORS@] "PIGEs and zero-position errors in the model's order [um, urad]";
pin in float r1_px; pin in float r1_py; pin in float r1_pz;
pin in float r1_ux; pin in float r1_uy; pin in float r1_uz;
pin in float r1_zero "twin: zero-position error [rad]";
pin in float r2_px; pin in float r2_py; pin in float r2_pz;
pin in float r2_ux; pin in float r2_uy; pin in float r2_uz = 1.0;
pin in float r2_zero "twin: zero-position error [rad]";
pin in float tool_length "stylus-tip centre below the gauge line [mm]";
pin in float sphere_x; pin in float sphere_y; pin in float sphere_z;
pin in float trip_radius "R + r - pre-travel [mm]";
pin out bit probe "tip centre within trip-radius of the sphere centre";
pin out float tip_x "stylus-tip centre in table coordinates [mm]";
pin out float tip_y;
pin out float tip_z;
pin out float gap "distance of the tip centre from the sphere centre minus trip-radius [mm]";
pin out float trip_gap "gap at the last rising edge of probe [mm]";
pin out s32 trips "rising edges of probe";
pin out float twin_diff "largest distance between the emitted model's and the twin's tip since loading [mm]";
pin out s32 model_failures "forward kinematics of the emitted model that did not converge";
pin out float clock "simulated time: the sum of the servo periods since loading [s]";
function _;
license "GPL";
;;
#include <rtapi_math.h>

@MODEL@

/* y <- q + R(u, phi) (y - q): Rodrigues rotation of y about the line through q along the unit vector u */
static void turn(double y[3], const double q[3], const double u[3], double phi)
{
    double v[3] = {y[0] - q[0], y[1] - q[1], y[2] - q[2]};
    double c = cos(phi), s = sin(phi);
    double d = u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
    double w[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
    int i;
    for (i = 0; i < 3; i++) y[i] = q[i] + c * v[i] + s * w[i] + (1.0 - c) * d * u[i];
}

/* the twin: undo the outer axis (the table turned by -t1 about it), then the inner one */
static void twin_tip(double y[3], double t1, double t2, const double q1[3], const double u1[3],
                     const double q2[3], const double u2[3])
{
    turn(y, q1, u1, t1);
    turn(y, q2, u2, t2);
}

FUNCTION(_) {
    @PREFIX@_params p;
    double lin[3] = {joint_x, joint_y, joint_z};
    double ang[2] = {joint_r1, joint_r2};
    double world[3], y[3] = {joint_x, joint_y, joint_z - tool_length};
    double q1[3] = {r1_px, r1_py, r1_pz}, u1[3] = {r1_ux, r1_uy, r1_uz};
    double q2[3] = {r2_px, r2_py, r2_pz}, u2[3] = {r2_ux, r2_uy, r2_uz};
    double dx, dy, dz, g;
    int i, was = probe;
    clock = clock + fperiod;
    @PREFIX@_params_init(&p);
    p.pivot[0][0] = pivot1_x; p.pivot[0][1] = pivot1_y; p.pivot[0][2] = pivot1_z;
    p.pivot[1][0] = pivot2_x; p.pivot[1][1] = pivot2_y; p.pivot[1][2] = pivot2_z;
    p.sense[0] = sense1; p.sense[1] = sense2;
    for (i = 0; i < @N_ERRORS@; i++) p.errors[i] = err(i);
    p.tool_offset = tool_length;
    if (@PREFIX@_forward(&p, lin, ang, world) != 0) model_failures = model_failures + 1;
    world[@PREFIX@_SPINDLE_AXIS] -= tool_length;  /* world holds the tool point plus the tool length */
    twin_tip(y, sense1 * joint_r1 * M_PI / 180.0 + r1_zero, sense2 * joint_r2 * M_PI / 180.0 + r2_zero,
             q1, u1, q2, u2);
    dx = world[0] - y[0]; dy = world[1] - y[1]; dz = world[2] - y[2];
    g = sqrt(dx * dx + dy * dy + dz * dz);
    if (g > twin_diff) twin_diff = g;
    tip_x = world[0]; tip_y = world[1]; tip_z = world[2];
    dx = world[0] - sphere_x; dy = world[1] - sphere_y; dz = world[2] - sphere_z;
    g = sqrt(dx * dx + dy * dy + dz * dz) - trip_radius;
    gap = g;
    probe = g <= 0.0;
    if (probe && !was) { trip_gap = g; trips = trips + 1; }
}
