"""Writes what genuine MediaPipe (pip mediapipe==0.10.21, Apache-2.0) reports for a photo, in
the two layouts users save: the Tasks API's HandLandmarkerResult (dataclasses.asdict, then
json.dumps) and the legacy Solutions API's results (MessageToDict of each hand).

    python dump_mediapipe.py PHOTO OUT_PREFIX HAND_LANDMARKER_TASK

writes OUT_PREFIX_tasks.json and OUT_PREFIX_legacy.json. The fixtures next to this script
were made from `bitt synth --scenes 6 --out S` (S/scene_000/train.png and
S/scene_005/train.png, 256 x 256). The Tasks API needs a `.task` bundle: the wheel ships
none, so it was zipped (stored) from the wheel's own models, as `hand_detector.tflite`
(mediapipe/modules/palm_detection/palm_detection_full.tflite) and
`hand_landmarks_detector.tflite` (mediapipe/modules/hand_landmark/hand_landmark_full.tflite).
"""

import dataclasses
import json
import sys

import mediapipe as mp
import numpy as np
from google.protobuf.json_format import MessageToDict
from mediapipe.tasks import python as tasks
from mediapipe.tasks.python import vision
from PIL import Image

photo, prefix, task = sys.argv[1:4]
pixels = np.asarray(Image.open(photo).convert("RGB"))

options = vision.HandLandmarkerOptions(
    base_options=tasks.BaseOptions(model_asset_path=task),
    num_hands=2,
    min_hand_detection_confidence=0.3,
    min_hand_presence_confidence=0.3,
)
with vision.HandLandmarker.create_from_options(options) as landmarker:
    result = landmarker.detect(mp.Image(image_format=mp.ImageFormat.SRGB, data=pixels))
with open(prefix + "_tasks.json", "w") as f:
    json.dump(dataclasses.asdict(result), f)

with mp.solutions.hands.Hands(
    static_image_mode=True, max_num_hands=2, min_detection_confidence=0.3
) as hands:
    result = hands.process(pixels)
legacy = {
    "multi_hand_landmarks": [MessageToDict(h) for h in result.multi_hand_landmarks or []],
    "multi_handedness": [MessageToDict(h) for h in result.multi_handedness or []],
}
with open(prefix + "_legacy.json", "w") as f:
    json.dump(legacy, f)
