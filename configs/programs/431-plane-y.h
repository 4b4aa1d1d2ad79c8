0 BEGIN PGM 431-plane-y MM
1 ; Cycle 431 MEASURE PLANE with the tool axis Y on the horizontal spindle of
2 ; configs/machines/horizontal-y-table-ac.toml, on the face of
3 ; configs/scenarios/tilted-plane-y.toml (expected Q158 = +5, Q159 = -3). With TOOL
4 ; CALL ... Y the 1st axis is Z, the 2nd X and the 3rd Y: the block is the one of
5 ; 431-plane.h, the probe comes from +Y and Q260 is a Y coordinate.
6 TOOL CALL "TOUCH_PROBE" Y
7 L Y+100 R0 FMAX
8 TCH PROBE 431 MEASURE PLANE ~
    Q263=+0        ;1ST POINT 1ST AXIS ~
    Q264=+0        ;1ST POINT 2ND AXIS ~
    Q294=+13       ;1ST POINT 3RD AXIS ~
    Q265=+50       ;2ND POINT 1ST AXIS ~
    Q266=+0        ;2ND POINT 2ND AXIS ~
    Q295=+15.7     ;2ND POINT 3RD AXIS ~
    Q296=+0        ;3RD POINT 1ST AXIS ~
    Q297=+50       ;3RD POINT 2ND AXIS ~
    Q298=+17.5     ;3RD POINT 3RD AXIS ~
    Q320=+0        ;SET-UP CLEARANCE ~
    Q260=+50       ;CLEARANCE HEIGHT ~
    Q281=+1        ;MEASURING LOG
9 L Y+100 R0 FMAX
10 M30
11 END PGM 431-plane-y MM
