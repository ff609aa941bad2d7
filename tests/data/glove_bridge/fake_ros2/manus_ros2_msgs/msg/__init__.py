"""MANUS's ROS 2 messages as the publisher defines them (ManusGlove.msg, ManusErgonomics.msg): plain classes with
the messages' fields, keyword-constructed like rosidl's generated Python classes."""


class ManusErgonomics:
    __slots__ = ("type", "value")

    def __init__(self, type="", value=0.0):  # noqa: A002 - the message's field is named `type`
        self.type, self.value = str(type), float(value)


class ManusGlove:
    __slots__ = (
        "glove_id",
        "side",
        "raw_node_count",
        "raw_nodes",
        "ergonomics_count",
        "ergonomics",
        "raw_sensor_orientation",
        "raw_sensor_count",
        "raw_sensor",
    )

    def __init__(self, **fields):
        unknown = set(fields) - set(self.__slots__)
        if unknown:
            raise TypeError(f"ManusGlove has no fields {sorted(unknown)}")
        for name in self.__slots__:
            setattr(self, name, fields.get(name))
