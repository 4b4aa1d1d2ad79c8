0 BEGIN PGM 450-save-restore MM
1 ; Cycle 450 SAVE KINEMATICS around a cycle 451 in mode 1, on
2 ; configs/scenarios/demo-sphere.toml: save the active kinematics under designation
3 ; 1, let 451 optimise and write the positions, then restore what was saved: the
4 ; kinematics file is as before the program (its 451 result stays in the protocol).
5 ; All of it in the machine's state directory, never configs/.
6 ; The probe is put over the sphere in machine coordinates (M91), whatever the
7 ; active preset; cycle 247 makes row 1, the sphere centre, the row Q431 sets,
8 ; so the program runs again and again, and row 0 stays at the machine origin.
9 ; Q408=50: before the rotary axes turn (unmonitored, at Q253=3000 deg/min) the
10 ; probe retracts to 50 mm over the sphere centre, 27 mm or more above the lowest
11 ; height that clears the sphere at every angle (a lower Q408 in `check` names it).
12 TOOL CALL "TOUCH_PROBE" Z
13 CYCL DEF 247 DATUM SETTING ~
    Q339=+1        ;DATUM NUMBER
14 TCH PROBE 450 SAVE KINEMATICS ~
    Q410=+0        ;MODE ~
    Q409=+1        ;MEMORY DESIGNATION
15 L Z+150 R0 FMAX M91
16 L A+0 C+0 R0 FMAX M91 ; the table level first, at the safe height: a run stopped mid-cycle leaves it tilted
17 L X+50 Y-30 R0 FMAX M91
18 L Z+102.5 R0 FMAX M91
19 TCH PROBE 451 MEASURE KINEMATICS ~
    Q406=+1        ;MODE ~
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
20 L Z+150 R0 FMAX M91
21 TCH PROBE 450 SAVE KINEMATICS ~
    Q410=+1        ;MODE ~
    Q409=+1        ;MEMORY DESIGNATION
22 END PGM 450-save-restore MM
