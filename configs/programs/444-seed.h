0 BEGIN PGM 444-seed MM
1 ; Cycle 444 block of the HEIDENHAIN manual (seed 003), verbatim: the value and
2 ; its comment stand on separate lines there, as the manual prints them.
10 TOOL CALL "TOUCH_PROBE" Z
11 TCH PROBE 444 ANTASTEN 3D ~

Q263=+0

;1. PUNKT 1. ACHSE ~

Q264=+0

;1. PUNKT 2. ACHSE ~

Q294=+0

;1. PUNKT 3. ACHSE ~

Q581=+1

;NORMALE HAUPTACHSE ~

Q582=+0

;NORMALE NEBENACHSE ~

Q583=+0

;NORMALE WKZ-ACHSE ~

Q320=+0

;Sicherheitsabstand ~

Q260=+100

;SICHERE HOEHE ~

QS400="1-1"

;TOLERANZ ~

Q309=+0

;FEHLERREAKTION
12 END PGM 444-seed MM
