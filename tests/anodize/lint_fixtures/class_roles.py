"""Roles as methods: a class-level list, and a module-level object whose methods are roles."""


class Station:
    log = []  # noqa: RUF012 - the shared class-level list is what the lint must find

    @classmethod
    def producer(cls, ep):
        cls.log.append("sent")
        ep.send("C", "stop")

    @staticmethod
    def consumer(ep):
        ep.recv("P")
        return Station.log


class Robot:
    def __init__(self):
        self.speed = 0

    def drive(self, ep):
        self.speed = 5
        ep.send("C", "stop")

    def watch(self, ep):
        ep.recv("P")
        return self._read()

    def _read(self):
        return self.speed


robot = Robot()
