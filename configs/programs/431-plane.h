0 BEGIN PGM 431-plane MM
1 ; Cycle 431 MEASURE PLANE on the face of configs/scenarios/tilted-plane.toml
2 ; (through X20 Y10 Z15; expected Q158 = +5, Q159 = -3). The nominal heights are
3 ; within reach on plane-z10.toml too (Q158 = Q159 = 0 there).
4 TOOL CALL "TOUCH_PROBE" Z
5 L Z+100 R0 FMAX
6 TCH PROBE 431 MEASURE PLANE ~
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
7 L Z+100 R0 FMAX
8 M30
9 END PGM 431-plane MM
