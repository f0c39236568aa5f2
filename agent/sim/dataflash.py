"""ArduPilot DataFlash (.bin) logs written with pymavlink's own DataFlash format classes: the
emulated ArduPlane's onboard log, and small generated logs for the importer's tests.

A DataFlash log is a stream of messages `A3 95 <type> <payload>`; FMT messages (type 128)
define every other type's name, struct format and column names before its first use. The
message definitions below follow ArduPilot's LogStructure (ArduPlane 4.x): names, format
characters (c = int16 × 0.01, so centidegrees; Q = µs time) and columns.
"""

from __future__ import annotations

import struct
from pathlib import Path

from pymavlink.DFReader import DFFormat

from agent.sim.logfile import LogFile

FMT_TYPE = 0x80
# name: (format characters, columns), ArduPilot's; shaped like agent.channels.SENSOR_CHANNELS only.
MESSAGES: dict[str, tuple[str, str]] = {
    "PARM": ("QNf", "TimeUS,Name,Value"),
    "MODE": ("QMBB", "TimeUS,Mode,ModeNum,Rsn"),
    "ATT": ("QccccCCCCB", "TimeUS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw,ErrRP,ErrYaw,AEKF"),
    "IMU": ("QBffffffIIfBBHH", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH,GHz,AHz"),
    "ARSP": ("QBffcffBBfB", "TimeUS,I,Airspeed,DiffPress,Temp,RawPress,Offset,U,H,Hp,Pri"),
    "AOA": ("Qff", "TimeUS,AOA,SSA"),
    # The EKF's state: EKF3's XKF1, EKF2's NKF1 (same layout); C is the EKF core.
    "XKF1": (
        "QBccCfffffffccce",
        "TimeUS,C,Roll,Pitch,Yaw,VN,VE,VD,dPD,PN,PE,PD,GX,GY,GZ,OH",
    ),
    "NKF1": (
        "QBccCfffffffccce",
        "TimeUS,C,Roll,Pitch,Yaw,VN,VE,VD,dPD,PN,PE,PD,GX,GY,GZ,OH",
    ),
    "RCIN": ("QHHHHHHHHHHHHHH", "TimeUS,C1,C2,C3,C4,C5,C6,C7,C8,C9,C10,C11,C12,C13,C14"),
    "RCOU": ("QHHHHHHHHHHHHHH", "TimeUS,C1,C2,C3,C4,C5,C6,C7,C8,C9,C10,C11,C12,C13,C14"),
    "SIDS": ("QBfffffff", "TimeUS,Ax,Mag,FSt,FSp,TFin,TC,TR,TFout"),
    "SIDD": ("Qfffffffff", "TimeUS,Time,Targ,F,Gx,Gy,Gz,Ax,Ay,Az"),
}


class DataFlashWriter(LogFile):
    """Append ArduPilot messages to a .bin file; `write("ATT", TimeUS=…, Roll=…)`."""

    def __init__(self, path: str | Path):
        super().__init__(path)
        self._fmt = DFFormat(FMT_TYPE, "FMT", 89, "BBnNZ", "Type,Length,Name,Format,Columns")
        self._formats: dict[str, DFFormat] = {}
        self.counts: dict[str, int] = {}

    def _format(self, name: str) -> DFFormat:
        fmt = self._formats.get(name)
        if fmt is None:
            letters, columns = MESSAGES[name]
            fmt = DFFormat(0x81 + len(self._formats), name, 0, letters, columns)
            fmt.len = 3 + struct.calcsize(fmt.msg_struct)  # the header counts
            self._formats[name] = fmt
            self._file.write(self._format_message(fmt))
        return fmt

    def _format_message(self, fmt: DFFormat) -> bytes:
        values = [
            fmt.type,
            fmt.len,
            fmt.name.encode(),
            fmt.format.encode(),
            ",".join(fmt.columns).encode(),
        ]
        return bytes([0xA3, 0x95, FMT_TYPE]) + struct.pack(self._fmt.msg_struct, *values)

    def write(self, name: str, **fields: float | int | str) -> None:
        """One message; fields not given are zero. Scaled formats take engineering units
        (degrees for c/C): the stored integer is value / multiplier, as ArduPilot stores it."""
        fmt = self._format(name)
        values = []
        for column, letter, mult in zip(fmt.columns, fmt.format, fmt.msg_mults, strict=True):
            value = fields.get(column, 0)
            if letter in "nNZa":
                value = str(value).encode()
            elif mult is not None:
                value = round(float(value) / mult)
            elif letter in "bBhHiIqQM":
                value = int(value)
            values.append(value)
        self._file.write(bytes([0xA3, 0x95, fmt.type]) + struct.pack(fmt.msg_struct, *values))
        self.counts[name] = self.counts.get(name, 0) + 1
