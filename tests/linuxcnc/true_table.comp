component pige_true_table "pige_sym test: the TRUE tilting table of a simulated trt machine and its touch probe";
description """
The true machine of tests/linuxcnc: from the joint feedback it computes where the stylus-tip centre is in
the table's own coordinates, with the exact rigid-body motion of CONVENTIONS §2-3 (two workpiece-side axis
lines, each a point and a unit direction, Rodrigues rotations), and trips the probe when the tip centre is
within trip-radius of the calibration sphere's centre.  Joint 3 is the outer axis (A or B, on the bed),
joint 4 the inner one (C, carried by the outer axis).  The carried body turns by -(sense * joint + zero)
about its line (a workpiece-side axis turns the table by -theta, theta = sense * commanded + zero).
""";
pin in float joint_x "joint 0 feedback [mm]";
pin in float joint_y "joint 1 feedback [mm]";
pin in float joint_z "joint 2 feedback [mm]: the spindle's reference point";
pin in float joint_r1 "joint 3 feedback [deg]: outer rotary axis";
pin in float joint_r2 "joint 4 feedback [deg]: inner rotary axis";
pin in float r1_px; pin in float r1_py; pin in float r1_pz;
pin in float r1_ux; pin in float r1_uy; pin in float r1_uz;
pin in float r1_sense = 1.0;
pin in float r1_zero "zero-position error [rad]";
pin in float r2_px; pin in float r2_py; pin in float r2_pz;
pin in float r2_ux; pin in float r2_uy; pin in float r2_uz = 1.0;
pin in float r2_sense = 1.0;
pin in float r2_zero "zero-position error [rad]";
pin in float tool_length "stylus-tip centre below the spindle's reference point [mm]";
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
    double y[3] = {joint_x, joint_y, joint_z - tool_length};
    double q1[3] = {r1_px, r1_py, r1_pz}, u1[3] = {r1_ux, r1_uy, r1_uz};
    double q2[3] = {r2_px, r2_py, r2_pz}, u2[3] = {r2_ux, r2_uy, r2_uz};
    double t1 = r1_sense * joint_r1 * M_PI / 180.0 + r1_zero;
    double t2 = r2_sense * joint_r2 * M_PI / 180.0 + r2_zero;
    double dx, dy, dz, g;
    int was = probe;
    clock = clock + fperiod;
    /* table point under the tip: undo the outer axis (the table turned by -t1), then the inner one */
    turn(y, q1, u1, t1);
    turn(y, q2, u2, t2);
    tip_x = y[0]; tip_y = y[1]; tip_z = y[2];
    dx = y[0] - sphere_x; dy = y[1] - sphere_y; dz = y[2] - sphere_z;
    g = sqrt(dx * dx + dy * dy + dz * dz) - trip_radius;
    gap = g;
    probe = g <= 0.0;
    if (probe && !was) { trip_gap = g; trips = trips + 1; }
}
