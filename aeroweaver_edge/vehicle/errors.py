"""Errors a vehicle backend raises through the Vehicle port."""


class VehicleError(RuntimeError):
    """A vehicle command could not be carried out (link lost, refused, wrong state).

    The flight-phase guard turns it into a hold of this UAV only; it never ends the daemon.
    """

    def explain(self) -> tuple[int, str]:
        return 1, f"vehicle: {self}"  # the vehicle link could not be brought up
