#!/bin/sh
# Calibrate the synthetic room's cameras from rendered board pictures and compare with the
# truth: the numbers and pictures of docs/calibrate.md.
#   sh docs/diag/calibrate_synthetic.sh OUTDIR [WIDTH HEIGHT [CAMERA_HEIGHT]]
# defaults 640 480 and the synthetic room's 2.6 m cameras; with DOCS=1 the check pictures are
# copied to docs/img/calibrate_check_cam0.png and docs/img/calibrate_check_top.png.
set -e
OUT=${1:?usage: calibrate_synthetic.sh OUTDIR [WIDTH HEIGHT [CAMERA_HEIGHT]]}
W=${2:-640}
H=${3:-480}
MBTRACK=${MBTRACK:-python -m mbtrack_ros.cli}
BOARD=charuco:5:4:0.25:0.19:DICT_4X4_50
CAMS="cam0 cam1 cam2 cam3 cam4"
$MBTRACK synth-board "$OUT/boards" --width "$W" --height "$H" --intrinsics-views 20 \
    ${4:+--camera-height $4}
INTR=""; FLOOR=""
for c in $CAMS; do
    INTR="$INTR $c=$OUT/boards/intrinsics/$c"
    FLOOR="$FLOOR $c=$OUT/boards/floor/$c.png"
done
$MBTRACK calibrate intrinsics "$OUT/intrinsics.yaml" --board $BOARD $INTR
# the board centred in the 6 x 5 m room (as synth-board puts it), the synthetic room's floor,
# entry zone and door
$MBTRACK calibrate extrinsics "$OUT/calibration.yaml" --intrinsics "$OUT/intrinsics.yaml" \
    --board $BOARD --board-pose 2.375,3,0 --floor 0.3,0.3,5.7,4.7 \
    --entry-zone 4.0,4.1,5.3,5.0 --exit 4.2,4.7,5.1,6.2 $FLOOR
$MBTRACK calibrate compare "$OUT/boards/calibration.yaml" "$OUT/calibration.yaml"
$MBTRACK calibrate check "$OUT/calibration.yaml" $FLOOR --out "$OUT/check"
if [ -n "$DOCS" ]; then
    cp "$OUT/check/cam0.png" docs/img/calibrate_check_cam0.png
    cp "$OUT/check/top.png" docs/img/calibrate_check_top.png
fi
