"""A third-party CANopen master (the Python `canopen` package) against our
simulated CiA 402 drive on vcan0: NMT reset and boot-up, expedited SDO both
ways and an abort, TPDO mapping, NMT start, heartbeat, SYNC -> TPDO.
Run inside the vcan VM while the drives are served (see .ci/vcan-tests)."""
import struct
import sys
import time

import canopen

NODE, LEAD_M, COUNTS = 2, 0.01, 4096
net = canopen.Network()
net.connect(interface="socketcan", channel="vcan0")
node = canopen.RemoteNode(NODE, canopen.ObjectDictionary())
net.add_node(node)
boot = []
net.subscribe(0x700 + NODE, lambda _cob, data, _ts: boot.append(bytes(data)))
# The drives' process may still be loading (a loaded machine without KVM
# has taken over 15 s): reset until a boot-up answers, for up to 90 s.
for _ in range(360):
    node.nmt.send_command(0x81)
    time.sleep(0.25)
    if b"\x00" in boot:
        break
assert b"\x00" in boot, f"no boot-up after NMT reset: {boot}"
sdo = node.sdo
sdo.download(0x6060, 0, struct.pack("<b", 8))
assert struct.unpack("<b", sdo.upload(0x6061, 0))[0] == 8
cob = 0x180 + NODE
for index, sub, data in [
    (0x1800, 1, struct.pack("<I", 0x80000000 | cob)),
    (0x1800, 2, b"\x01"),
    (0x1A00, 0, b"\x00"),
    (0x1A00, 1, struct.pack("<I", 0x60410010)),
    (0x1A00, 2, struct.pack("<I", 0x60640020)),
    (0x1A00, 0, b"\x02"),
    (0x1800, 1, struct.pack("<I", cob)),
    (0x1017, 0, struct.pack("<H", 10)),
]:
    sdo.download(index, sub, data)
# How the drive stops (CiA 402 option codes): it powers on coasting on a
# fault (0x605E = 0, as many drives), takes the quick stop ramp when told
# (2) and says so when asked; the same for the abort connection option.
assert struct.unpack("<h", sdo.upload(0x605E, 0))[0] == 0
for index, value in [(0x605A, 6), (0x605C, 1), (0x605E, 2), (0x6007, 3)]:
    sdo.download(index, 0, struct.pack("<h", value))
    assert struct.unpack("<h", sdo.upload(index, 0))[0] == value, hex(index)
try:
    sdo.upload(0x2000, 0)
    sys.exit("no abort for a missing object")
except canopen.SdoAbortedError as e:
    assert e.code == 0x06020000, hex(e.code)
node.nmt.state = "OPERATIONAL"
time.sleep(0.1)  # a heartbeat already on its way may still say pre-operational
node.nmt.wait_for_heartbeat(1)
assert node.nmt.state == "OPERATIONAL", node.nmt.state
got = []
net.subscribe(cob, lambda _cob, data, _ts: got.append(bytes(data)))
net.sync.transmit()
time.sleep(0.2)
assert got, "no TPDO after SYNC"
sw, pos = struct.unpack("<Hi", got[0])
assert pos == round(0.28 / (LEAD_M / COUNTS)), pos
assert sw & 0x8000 and sw & 0x4F == 0x40, hex(sw)
net.disconnect()
print("python-canopen peer: OK (SDO, abort, NMT, heartbeat, PDO mapping, SYNC/TPDO, stop options)")
