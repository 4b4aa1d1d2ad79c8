0 BEGIN PGM 451-head-b MM
1 ; Cycle 451 MEASURE KINEMATICS, mode 0 (check), on configs/scenarios/head-b-table-c.toml:
2 ; the calibration sphere R12.5 at X+40 Y+25 Z+60 on the machine with a B swivel head
3 ; and a C rotary table. The probe goes over the sphere, 5 mm above Q320 + SET_UP over
4 ; its pole; cycle 451 finds the sphere from there (Q431=1; mode 0 writes nothing, so
5 ; neither the preset nor the kinematics change). B tilts the probe from -60 to +60
6 ; degrees: the pole and the points follow the tilted tool axis.
7 ; Q408=50: before the rotary axes turn (unmonitored, at Q253=3000 deg/min) the
8 ; probe retracts to 50 mm over the sphere centre, 27 mm or more above the lowest
9 ; height that clears the sphere at every angle (a lower Q408 in `check` names it).
10 TOOL CALL "TOUCH_PROBE" Z
11 L Z+150 R0 FMAX M91
12 L B+0 C+0 R0 FMAX M91 ; the head upright first, at the safe height
13 L X+40 Y+25 R0 FMAX M91
14 L Z+82.5 R0 FMAX M91
15 TCH PROBE 451 MEASURE KINEMATICS ~
    Q406=+0        ;MODE ~
    Q407=+12.5     ;SPHERE RADIUS ~
    Q320=+0        ;SET-UP CLEARANCE ~
    Q408=+50       ;RETR. HEIGHT ~
    Q253=+3000     ;F PRE-POSITIONING ~
    Q380=+0        ;REFERENCE ANGLE ~
    Q411=+0        ;START ANGLE A AXIS ~
    Q412=+0        ;END ANGLE A AXIS ~
    Q413=+0        ;INCID. ANGLE A AXIS ~
    Q414=+0        ;MEAS. POINTS A AXIS ~
    Q415=-60       ;START ANGLE B AXIS ~
    Q416=+60       ;END ANGLE B AXIS ~
    Q417=+0        ;INCID. ANGLE B AXIS ~
    Q418=+4        ;MEAS. POINTS B AXIS ~
    Q419=+90       ;START ANGLE C AXIS ~
    Q420=+270      ;END ANGLE C AXIS ~
    Q421=+0        ;INCID. ANGLE C AXIS ~
    Q422=+3        ;MEAS. POINTS C AXIS ~
    Q423=+4        ;NO. OF PROBE POINTS ~
    Q431=+1        ;PRESET ~
    Q432=+0        ;BACKLASH, ANG. RANGE
16 L Z+150 R0 FMAX M91
17 END PGM 451-head-b MM
