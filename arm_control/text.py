"""Text from the outside world, made safe to put in a log line or an event."""

QUOTE_CHARS = 40


def quote(text: str, limit: int = QUOTE_CHARS) -> str:
    """``text`` in quotes, or its first ``limit`` characters and its length when longer: a
    frame id or preset name from a message may be megabytes long."""
    if len(text) <= limit:
        return repr(text)
    return f'{text[:limit]!r}... ({len(text)} characters)'
