0 BEGIN PGM 460-calibrate MM
1 ; Cycle 460 CALIBRATION OF TS ON A SPHERE on configs/scenarios/demo-sphere.toml:
2 ; the calibration sphere R12.5 at X+50 Y-30 Z+80 (machine coordinates, the preset
3 ; table's row 0 active, at the machine origin: Q434 is the sphere centre's Z).
4 ; The probe is put over the sphere (M91: machine coordinates, whatever the active
5 ; preset), about SET_UP + Q320 above its pole; the cycle probes the pole, Q423 points
6 ; around the equator (at spindle 0 deg and 180 deg where the spindle can be
7 ; oriented), the pole again, and writes the probe's row (R, CAL_OF1, CAL_OF2,
8 ; CAL_ANG, L) to <machine>.probes.toml in the machine's state directory. Run it
9 ; before 451, and again whenever the stylus was changed or knocked.
10 TOOL CALL "TOUCH_PROBE" Z
11 L Z+150 R0 FMAX M91
12 L A+0 C+0 R0 FMAX M91 ; the table level first, at the safe height: a run stopped mid-cycle leaves it tilted
13 L X+50 Y-30 R0 FMAX M91
14 L Z+98.5 R0 FMAX M91
15 TCH PROBE 460 CALIBRATION OF TS ON A SPHERE ~
    Q407=+12.5     ;RADIUS OF CALIB. SPHERE ~
    Q320=+0        ;SET-UP CLEARANCE ~
    Q301=+1        ;MOVE TO CLEARANCE ~
    Q423=+8        ;NO. OF PROBE POINTS ~
    Q380=+0        ;REFERENCE ANGLE ~
    Q433=+1        ;CALIBRATE LENGTH ~
    Q434=+80       ;DATUM FOR LENGTH ~
    Q455=+0        ;NO. OF POINTS IN 3D CAL.
16 L Z+150 R0 FMAX M91
17 END PGM 460-calibrate MM
