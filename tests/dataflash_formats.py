"""ArduPlane's DataFlash message formats (type, struct format, columns, as ``AP_Logger`` writes them), shared by
the tests that write DataFlash logs (``tests/test_dataflash.py``) and the README's test (``tests/test_readme.py``),
which checks the README's ArduPlane signal map against the same messages.
"""

from __future__ import annotations

# ArduPlane's messages (names and columns as AP_Logger writes them; ATT in centidegrees as in ArduPilot 4.x)
FORMATS = {
    "ATT": (129, "QccccCCCC", "TimeUS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw,ErrRP,ErrYaw"),
    "RATE": (130, "Qffffffffffff", "TimeUS,RDes,R,ROut,PDes,P,POut,YDes,Y,YOut,ADes,A,AOut"),
    "AOA": (131, "Qff", "TimeUS,AOA,SSA"),
    "RCOU": (132, "QHHHHHHHHHHHHHH", "TimeUS,C1,C2,C3,C4,C5,C6,C7,C8,C9,C10,C11,C12,C13,C14"),
    "ARSP": (133, "QBfff", "TimeUS,I,Airspeed,DiffPress,Temp"),
    "PARM": (134, "QNf", "TimeUS,Name,Value"),
    "CTUN": (135, "Qccccf", "TimeUS,NavRoll,Roll,NavPitch,Pitch,As"),  # declared, never written
}
