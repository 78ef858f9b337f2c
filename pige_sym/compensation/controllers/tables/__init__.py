"""The error maps of the rotary axes (CONVENTIONS §10) in the controllers' own compensation tables.

One module per table, each citing the manual (document and page) that settles its format, units, sign and
interpolation, and refusing with the reason what the pages read do not settle:

- :mod:`.positioning`: what every positioning table is made from: the positioning error φ (and E) of a rotary
  axis in its commanded angle and sense (CONVENTIONS §9), per direction of motion where the map has both;
- :mod:`.linuxcnc_comp`: LinuxCNC ``[JOINT_n]COMP_FILE`` (``COMP_FILE_TYPE = 1``);
- :mod:`.siemens_lec`: SINUMERIK leadscrew / measuring system error compensation ``$AA_ENC_COMP``;
- :mod:`.isg_ssfk`: ISG kernel (Beckhoff TwinCAT CNC) leadscrew error compensation list ``kw.ssfk``;
- :mod:`.refused`: FANUC pitch error compensation, HEIDENHAIN nonlinear axis error compensation and the ISG
  volumetric compensation: what their pages settle, and why no value is written.

This package holds no controller (``pige compensate --controller`` lists the modules of the parent package).
"""
