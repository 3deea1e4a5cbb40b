"""A .wpilog read back with WPILib's own reader, for tests of what the project writes."""


def read_wpilog(path) -> dict:
    """{entry name: (type, metadata, [(timestamp µs, value), ...])} from a .wpilog."""
    from wpiutil.log import DataLogReader
    reader = DataLogReader(str(path))
    assert reader.isValid()
    starts, entries = {}, {}
    for record in reader:
        if record.isStart():
            start = record.getStartData()
            starts[start.entry] = start.name
            entries[start.name] = (start.type, start.metadata, [])
        elif not record.isControl():
            name = starts[record.getEntry()]
            kind = entries[name][0]
            value = {'double[]': record.getDoubleArray, 'double': record.getDouble,
                     'boolean': record.getBoolean, 'string': record.getString}[kind]()
            entries[name][2].append((record.getTimestamp(), value))
    return entries
