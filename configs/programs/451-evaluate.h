0 BEGIN PGM 451-evaluate MM
1 ; Cycle 451 in mode 0 on configs/scenarios/demo-sphere.toml (as 451-check.h), then
2 ; the program evaluates what it measured: the C axis's location errors out of QS146
3 ; as the seed shows it (SUBSTR/TONUMB), and the shift stops through FN 14 when the
4 ; measured dispersion of A or C exceeds the limit in QL10.
5 ; Q408=50: before the rotary axes turn (unmonitored, at Q253=3000 deg/min) the
6 ; probe retracts to 50 mm over the sphere centre, 27 mm or more above the lowest
7 ; height that clears the sphere at every angle (a lower Q408 in `check` names it).
8 QL10 = 0.05 ; dispersion limit, mm
9 TOOL CALL "TOUCH_PROBE" Z
10 L Z+150 R0 FMAX
11 L A+0 C+0 R0 FMAX M91 ; the table level first, at the safe height: a run stopped mid-cycle leaves it tilted
12 L X+50 Y-30 R0 FMAX
13 L Z+102.5 R0 FMAX
14 TCH PROBE 451 MEASURE KINEMATICS ~
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
    Q431=+1        ;PRESET ~
    Q432=+0        ;BACKLASH, ANG. RANGE
15 QS0 = SUBSTR ( SRC_QS146 BEG0 LEN10 ) ; EX0C
16 QL0 = TONUMB ( SRC_QS0 )
17 QS0 = SUBSTR ( SRC_QS146 BEG11 LEN10 ) ; EY0C
18 QL1 = TONUMB ( SRC_QS0 )
19 QS0 = SUBSTR ( SRC_QS146 BEG22 LEN10 ) ; EA0C
20 QL2 = TONUMB ( SRC_QS0 )
21 QS0 = SUBSTR ( SRC_QS146 BEG33 LEN10 ) ; EB0C
22 QL3 = TONUMB ( SRC_QS0 )
23 Q10 = SQRT ( SQ QL0 + SQ QL1 ) * 1000 ; C axis position error, um
24 FN 11: IF +Q141 GT +QL10 GOTO LBL 99
25 FN 11: IF +Q143 GT +QL10 GOTO LBL 99
26 L Z+150 R0 FMAX
27 M30
28 LBL 99
29 L Z+150 R0 FMAX
30 FN 14: ERROR = 1001
31 END PGM 451-evaluate MM
