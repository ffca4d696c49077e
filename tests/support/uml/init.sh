#!/bin/sh
# init (PID 1) of a User Mode Linux guest whose root is the host's / (hostfs): the host kernel has no
# SocketCAN, this one does. Runs the socketcan tests (or the script UML_SCRIPT names), leaves their output and exit code in UML_RESULT_DIR
# on the shared filesystem, and powers off. Unknown kernel parameters (UML_*) arrive here as environment.
export PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin
mount -t proc proc /proc
mount -t sysfs sysfs /sys
mount -t tmpfs tmpfs /run
mkdir -p /dev/shm && mount -t tmpfs tmpfs /dev/shm   # /dev is the guest's devtmpfs: no shm directory until made
mkdir -p /dev/pts && mount -t devpts devpts /dev/pts
modules=${UML_MODULES:-/usr/lib/uml/modules}/$(uname -r)/kernel   # UML_MODULES: .uml/'s newer UML
for module in net/can/can.ko net/can/can-raw.ko drivers/net/can/dev/can-dev.ko drivers/net/can/vcan.ko; do
    insmod "$modules/$module" 2>>"$UML_RESULT_DIR/output.txt"
done
ip link add dev vcan0 type vcan 2>>"$UML_RESULT_DIR/output.txt"
# CAN FD MTU (72): classic frames pass as before, and FD streams (one 64-byte frame per RawIMU) can be sent
ip link set vcan0 mtu 72 2>>"$UML_RESULT_DIR/output.txt"
ip link set vcan0 up 2>>"$UML_RESULT_DIR/output.txt"
cd "$UML_REPO" || echo "no repo at $UML_REPO" >>"$UML_RESULT_DIR/output.txt"
export HOME=/root IMU_EMULATOR_IN_UML=1 TMPDIR=/dev/shm
if [ -n "$UML_SCRIPT" ]; then   # e.g. tools/bench_coexist.py's guest half
    sh "$UML_SCRIPT" >>"$UML_RESULT_DIR/output.txt" 2>&1
else
    "$UML_PYTHON" -m pytest -m socketcan tests/live/socketcan -q -p no:cacheprovider -o addopts="" \
        >>"$UML_RESULT_DIR/output.txt" 2>&1
fi
echo $? > "$UML_RESULT_DIR/exit_code"
sync
# Power-off is asynchronous: if init exited first the kernel would panic.
echo o > /proc/sysrq-trigger
sleep 30
