"""Text to the terminal, whatever its encoding: the one writer of every command (``gyro-sim``, its sweeps).
"""


def _write(stream, text: str) -> None:
    """Write text, replacing characters the stream's encoding cannot show (θ, ·)."""
    try:
        stream.write(text)
    except UnicodeEncodeError:
        enc = getattr(stream, "encoding", None) or "ascii"
        stream.write(text.encode(enc, "replace").decode(enc))
