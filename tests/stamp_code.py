"""The stamp camera_node's test source draws into each frame (nodes/camera_node/src/code.rs),
read back from an image: for the tests (rclpy's venv) and tests/lerobot_load.py (lerobot's),
so without ROS."""


def read_code(img):
    """The stamp (ns) drawn by the test source: five rows of 16 blocks (black = 1) at the
    top left, block side min(w // 18, h // 16, 16) px, one block of margin; the words are
    sec (high, low), nanosec (high, low) and the complement of their XOR."""
    w, h = img.size
    b = min(w // 18, h // 16, 16)
    gray = img.convert("L")
    words = []
    for row in range(5):
        word = 0
        for bit in range(16):
            x, y = b * (1 + bit), b * (1 + row)
            box = gray.crop((x + b // 4, y + b // 4, x + b // 4 + b // 2, y + b // 4 + b // 2))
            pixels = box.tobytes()  # one byte a pixel (mode L)
            word = word << 1 | (sum(pixels) / len(pixels) < 128)
        words.append(word)
    assert words[4] == ~(words[0] ^ words[1] ^ words[2] ^ words[3]) & 0xFFFF, f"check word of {words}"
    sec = words[0] << 16 | words[1]
    sec -= (sec >> 31) << 32  # int32
    return sec * 1_000_000_000 + (words[2] << 16 | words[3])
