0 BEGIN PGM 451-preset-247 MM
1 ; Cycle 451 MEASURE KINEMATICS, mode 0 (check), on configs/scenarios/demo-sphere.toml,
2 ; with Q431=0 as on the TNC: the operator set the preset at the sphere centre (row 1
3 ; of configs/machines/table-ac.presets.toml: X+50 Y-30 Z+80), cycle 247 activates it,
4 ; and cycle 451 goes over the sphere from wherever the probe stands, here 100 mm away;
5 ; no L block over the sphere, no locating measurement. Q147..Q149 are the sphere
6 ; centre relative to preset 1 (about 0). Mode 0 changes nothing.
7 ; Q408=50: before the rotary axes turn (unmonitored, at Q253=3000 deg/min) the
8 ; probe retracts to 50 mm over the sphere centre, 27 mm or more above the lowest
9 ; height that clears the sphere at every angle (a lower Q408 in `check` names it).
10 TOOL CALL "TOUCH_PROBE" Z
11 L Z+150 R0 FMAX M91
12 L A+0 C+0 R0 FMAX M91 ; the table level first, at the safe height: a run stopped mid-cycle leaves it tilted
13 CYCL DEF 247 DATUM SETTING ~
    Q339=+1        ;DATUM NUMBER
14 L X+0 Y+100 R0 FMAX
15 L Z+30 R0 FMAX
16 ; the probe is 100 mm from the sphere in Y
17 TCH PROBE 451 MEASURE KINEMATICS ~
    Q406=+0        ;MODE ~
    Q407=+12.5     ;SPHERE RADIUS ~
    Q320=+0        ;SET-UP CLEARANCE ~
    Q408=+50       ;RETR. HEIGHT ~
    Q253=+3000     ;F PRE-POSITIONING ~
    Q380=+0        ;REFERENCE ANGLE ~
    Q411=-90       ;START ANGLE A AXIS ~
    Q412=+90       ;END ANGLE A AXIS ~
    Q413=+0        ;INCID. ANGLE A AXIS ~
    Q414=+3        ;MEAS. POINTS A AXIS ~
    Q415=+0        ;START ANGLE B AXIS ~
    Q416=+0        ;END ANGLE B AXIS ~
    Q417=+0        ;INCID. ANGLE B AXIS ~
    Q418=+0        ;MEAS. POINTS B AXIS ~
    Q419=+90       ;START ANGLE C AXIS ~
    Q420=+270      ;END ANGLE C AXIS ~
    Q421=+0        ;INCID. ANGLE C AXIS ~
    Q422=+3        ;MEAS. POINTS C AXIS ~
    Q423=+4        ;NO. OF PROBE POINTS ~
    Q431=+0        ;PRESET ~
    Q432=+0        ;BACKLASH, ANG. RANGE
18 L Z+70 R0 FMAX
19 END PGM 451-preset-247 MM
