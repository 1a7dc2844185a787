"""ArduPlane's DataFlash message formats (type, struct format, columns, as ``AP_Logger`` writes them), shared by
the tests that write DataFlash logs (``tests/test_dataflash.py``, ``tests/test_derived_signals.py``) and the README's
test (``tests/test_readme.py``), which checks the README's ArduPlane signal map against the same messages; and the
writer of such logs (``write_dataflash``) with a short-period flight to write (``short_period_flight``).
"""

from __future__ import annotations

import random
import struct
from pathlib import Path

import numpy as np

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


HEAD = b"\xa3\x95"
_STRUCT = {
    "B": "B",
    "H": "H",
    "I": "I",
    "Q": "Q",
    "f": "f",
    "c": "h",
    "C": "H",
    "h": "h",
    "n": "4s",
    "N": "16s",
    "Z": "64s",
}
_MULT = {"c": 100.0, "C": 100.0}  # stored as hundredths: DFReader divides by 100
ARDUPLANE_MAP = """
[signals]
instant = "RCOU"                  # the servo outputs' TimeUS is the sample's instant
actuator = ["elevator"]
[signals.measured]
alpha = { field = "AOA.AOA", unit = "deg" }
q = { field = "RATE.P", unit = "deg/s" }
theta = { field = "ATT.Pitch", unit = "deg" }
airspeed = { field = "ARSP.Airspeed", unit = "m/s" }
elevator = { field = "RCOU.C2", scale = 0.06, offset = -90.0, unit = "deg" }
"""
T0_US = 183_456_789  # the autopilot's boot time at the first sample: any phase of its clock


def pack_record(name: str, values: list) -> bytes:
    mtype, fmt, _cols = FORMATS[name]
    scaled = [round(v * _MULT[c]) if c in _MULT else v for c, v in zip(fmt, values, strict=True)]
    return HEAD + bytes((mtype,)) + struct.pack("<" + "".join(_STRUCT[c] for c in fmt), *scaled)


def fmt_record(name: str, formats: dict[str, tuple[int, str, str]] = FORMATS) -> bytes:
    mtype, fmt, cols = formats[name]
    length = 3 + struct.calcsize("<" + "".join(_STRUCT[c] for c in fmt))
    return HEAD + b"\x80" + struct.pack("<BB4s16s64s", mtype, length, name.encode(), fmt.encode(), cols.encode())


def write_dataflash(path: Path, samples: list[dict[str, float]], h: float, seed: int = 0, text: bool = False) -> None:
    """Each sample k: ATT, RATE, AOA, RCOU, ARSP records stamped T0 + k h + a random 0-8 ms each, in TimeUS order;
    FMT records first (FMT's own, then one per message), a PARM record among them."""
    rng = random.Random(seed)
    records: list[tuple[int, str, list]] = [(T0_US - 500_000, "PARM", [T0_US - 500_000, b"SYSID_THISMAV", 1.0])]
    for k, s in enumerate(samples):
        base = T0_US + round(k * h * 1e6)
        pwm = int(s["pwm"])
        for name, values in (
            ("ATT", [0.0, 0.0, s["theta"], s["theta"], 90.0, 90.0, 0.0, 0.0]),
            ("RATE", [0.0, 0.0, 0.0, s["q"], s["q"], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
            ("AOA", [s["alpha"], 0.0]),
            ("RCOU", [1500, pwm, 1200, 1500] + [0] * 10),
            ("ARSP", [0, s.get("airspeed", 25.0), 100.0, 20.0]),
        ):
            t = base + rng.randint(0, 8000)
            records.append((t, name, [t, *values]))
    records.sort(key=lambda r: r[0])
    if text:
        lines = ["FMT, 128, 89, FMT, BBnNZ, Type,Length,Name,Format,Columns"]
        for name, (mtype, fmt, cols) in FORMATS.items():
            length = 3 + struct.calcsize("<" + "".join(_STRUCT[c] for c in fmt))
            lines.append(f"FMT, {mtype}, {length}, {name}, {fmt}, {cols}")
        for _t, name, values in records:
            cells = [
                v.decode() if isinstance(v, bytes) else (f"{v:.9g}" if isinstance(v, float) else str(v)) for v in values
            ]
            lines.append(", ".join([name, *cells]))
        path.write_text("\n".join(lines) + "\n")
        return
    with open(path, "wb") as fh:
        fh.write(fmt_of_fmt() + b"".join(fmt_record(n) for n in FORMATS))
        for _t, name, values in records:
            fh.write(pack_record(name, values))


def fmt_of_fmt() -> bytes:
    return HEAD + b"\x80" + struct.pack("<BB4s16s64s", 128, 89, b"FMT", b"BBnNZ", b"Type,Length,Name,Format,Columns")


def short_period_flight(h: float = 0.02, lead_s: float = 3.0, seconds: float = 30.0, seed: int = 1):
    """A linear short-period aircraft (alpha deg, q deg/s; elevator deg about trim -3 deg) flown with an
    elevator PRBS of +-1 deg, dwell 0.2-1 s: the true A_c, B_c and the samples (elevator as servo PWM)."""
    from scipy.linalg import expm

    A = np.array([[-2.0, 1.0], [-15.0, -3.0]])
    B = np.array([[-0.2], [-12.0]])
    M = expm(np.block([[A, B], [np.zeros((1, 3))]]) * h)
    Ad, Bd = M[:2, :2], M[:2, 2:]
    rng = np.random.default_rng(seed)
    n_lead, n = round(lead_s / h), round((lead_s + seconds) / h)
    u_dev, sign, left = [], 1.0, 0
    for k in range(n):
        if k < n_lead:
            u_dev.append(0.0)
            continue
        if left == 0:
            sign, left = -sign, int(rng.integers(round(0.2 / h), round(1.0 / h) + 1))
        u_dev.append(sign)
        left -= 1
    trim_u, trim_alpha, x, theta = -3.0, 2.0, np.zeros(2), 2.0
    samples = []
    for k in range(n):
        pwm = round(1500 + (trim_u + u_dev[k]) / 0.06)
        u = (pwm - 1500) * 0.06 - trim_u  # what the servo flew: the PWM's own resolution
        samples.append({"alpha": trim_alpha + x[0], "q": x[1], "theta": theta, "pwm": pwm})
        theta += x[1] * h
        x = Ad @ x + (Bd * u).ravel()
    return A, B, samples
