component pige_true_mixed "pige_sym test: the TRUE mixed machine (C table, B head) of a simulated xyzbc machine and its touch probe";
description """
The true machine of tests/linuxcnc/test_linuxcnc_head.py, written in the test from CONVENTIONS 2, 3 and 7
(no pige code): joint 3 is a swivel head B carrying the probe, joint 4 a rotary table C carrying the
sphere, both with their true lines (a point and a unit direction each, exact Rodrigues rotations).  With
identity kinematics the linear joints less the tool length are where the stylus-tip centre would be with the
head at its reference pose; the head turns the tip about its true line by +(sense * joint + zero), the table
turns the sphere by -(sense * joint + zero).  The probe trips when the tip centre, taken into the table's own
coordinates, is within trip-radius of the sphere's centre.
""";
pin in float joint_x "joint 0 feedback [mm]";
pin in float joint_y "joint 1 feedback [mm]";
pin in float joint_z "joint 2 feedback [mm]: the spindle's gauge line";
pin in float joint_head "joint 3 feedback [deg]: the head axis (B)";
pin in float joint_table "joint 4 feedback [deg]: the table axis (C)";
pin in float head_px; pin in float head_py; pin in float head_pz;
pin in float head_ux; pin in float head_uy = 1.0; pin in float head_uz;
pin in float head_zero "zero-position error [rad]";
pin in float head_sense = 1.0;
pin in float b0_x "stylus-tip centre at the reference pose: nominal head pivot + tool [mm]";
pin in float b0_y; pin in float b0_z;
pin in float table_px; pin in float table_py; pin in float table_pz;
pin in float table_ux; pin in float table_uy; pin in float table_uz = 1.0;
pin in float table_zero "zero-position error [rad]";
pin in float table_sense = 1.0;
pin in float tool_length "gauge line to the tool's controlled point (G43) [mm]";
pin in float sphere_x; pin in float sphere_y; pin in float sphere_z;
pin in float trip_radius "R + r - pre-travel [mm]";
pin out bit probe "tip centre within trip-radius of the sphere centre";
pin out float tip_x "stylus-tip centre in table coordinates [mm]";
pin out float tip_y;
pin out float tip_z;
pin out float gap "distance of the tip centre from the sphere centre minus trip-radius [mm]";
pin out float trip_gap "gap at the last rising edge of probe [mm]";
pin out s32 trips "rising edges of probe";
pin out float clock "simulated time: the sum of the servo periods since loading [s]";
function _;
license "GPL";
;;
#include <rtapi_math.h>

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

FUNCTION(_) {
    double qh[3] = {head_px, head_py, head_pz}, uh[3] = {head_ux, head_uy, head_uz};
    double qt[3] = {table_px, table_py, table_pz}, ut[3] = {table_ux, table_uy, table_uz};
    double b[3] = {b0_x, b0_y, b0_z}, y[3];
    double dx, dy, dz, g;
    int was = probe;
    clock = clock + fperiod;
    /* the head turns the tip about its true line: b -> T(theta)(b0), machine frame at the reference pose */
    turn(b, qh, uh, (head_sense < 0.0 ? -1.0 : 1.0) * joint_head * M_PI / 180.0 + head_zero);
    y[0] = joint_x + b[0] - b0_x;
    y[1] = joint_y + b[1] - b0_y;
    y[2] = joint_z - tool_length + b[2] - b0_z;
    /* the table turned the sphere by -theta: turning the tip by +theta takes it into table coordinates */
    turn(y, qt, ut, (table_sense < 0.0 ? -1.0 : 1.0) * joint_table * M_PI / 180.0 + table_zero);
    tip_x = y[0]; tip_y = y[1]; tip_z = y[2];
    dx = y[0] - sphere_x; dy = y[1] - sphere_y; dz = y[2] - sphere_z;
    g = sqrt(dx * dx + dy * dy + dz * dz) - trip_radius;
    gap = g;
    probe = g <= 0.0;
    if (probe && !was) { trip_gap = g; trips = trips + 1; }
}
