"""The monitor's MAVLink link layer, one step per module, so a reader sees where a byte becomes a sample.

    transports  bytes in/out per link and peer (udpin, udpout, tcp, tcpin; a tlog file in ``tlog``)
        |
    frames      one parser per stream (partial frames kept across reads) or per datagram; CRC and
        |       signature (``signing``) checked; every reject counted
    signals     the signal map: which MESSAGE.field[index] is each plant output, the actuator report,
        |       the command channel, which message defines the sampling instant, the operating point
    assembly    per vehicle, parts of one sampling instant gathered into one sample, bounded waiting;
        |       a message without a time field (VFR_HUD) is a latest value (sample and hold)
        |
    monitor.service.vehicles -> monitor.model.estimator   (the vehicle table and eqs. (5)-(6))

``fault-monitor run`` and ``fault-monitor analyse`` share everything from ``frames`` down; the only
difference is whether a command goes back (``monitor.service.pipeline``). Frames are MAVLink 1 or 2.

Logs: ``tlog`` (a MAVLink byte source), ``dataflash`` (ArduPilot's on-board logs through pymavlink's DFReader:
records by name, TimeUS the clock, fed to the same signal map and assembler), ``log_inventory`` (what a log
holds), ``flight_log`` (a log's samples for ``identify``).
"""
