"""The simulator playing a built plate: a nominal design, hidden deviations, and the FEM of the plate as built.

The plate the bench "measures" is the FEM of :func:`workflow.models.builtplate.deviated_plate`:
its working mode gives the simulated resonance f_r and the quasi-static deflection per volt at
the centre (an antinode), the Q(v) law and the drift stay those of :mod:`.physics`.  Away from
the centre the velocity follows the FEM's full modal superposition at the drive frequency
(:class:`~workflow.models.fem.surface.SurfaceModes`, transverse modes included), relative to the
working mode at the centre:

    v(x, y) = v_centre(f, V, t) * w(x, y, f', Q) / w_working(0, 0, f', Q),

with v_centre the single-mode response of :class:`.physics.PlateResponse`, Q = Q(v_centre) and
f' = f f_r / f_r(t) the drive frequency seen relative to the drifted resonance.
"""

from dataclasses import dataclass

from instruments.simulator.physics import PlateResponse, default_law
from instruments.simulator.thermal import thermal_model
from workflow.models.builtplate import BuiltPlate, PlateDeviations, deviated_plate
from workflow.models.fem import FemResult
from workflow.models.fem.accuracy import SIMULATION_ACCURACY_TARGET, FemAccuracy
from workflow.models.fem.settings import FemSettings
from workflow.models.fem.surface import SurfaceModes, evaluate_surface
from workflow.models.materials import DESIGN_VOLTAGE, PLATE_Q
from workflow.models.plate import Plate

SIMULATION_ACCURACY = FemAccuracy(target=SIMULATION_ACCURACY_TARGET)
"""FEM accuracy of a simulated built plate (:data:`~workflow.models.fem.accuracy.SIMULATION_ACCURACY_TARGET`)."""


@dataclass(frozen=True, eq=False)
class BuiltPlateModel:
    """A built plate as the simulator plays it.

    Attributes
    ----------
    nominal : BuiltPlate
        The design the logs name.
    deviations : PlateDeviations
        The hidden differences of the plate as built.
    result : FemResult
        FEM of the deviated plate (its best mode is the working mode).
    surface : SurfaceModes
        Its modes over the top face.
    """

    nominal: BuiltPlate
    deviations: PlateDeviations
    result: FemResult
    surface: SurfaceModes

    @property
    def resonance_frequency(self) -> float:
        """f_r of the plate as built [Hz]."""
        return float(self.result.frequency)

    @property
    def deflection_per_volt(self) -> float:
        """Quasi-static deflection of the working mode at the centre per volt [m/V]: |phi(0) F| / omega^2 / V
        times the drive factor of the ceramics' offset."""
        model, m = self.surface.at(0.0, 0.0), self.surface.working_mode
        static = abs(model.probe_shapes[0, m] * model.modal_forces[m]) / model.eigenvalues[m]
        return float(static / self.result.voltage * self.deviations.drive_factor(self.nominal.wavelength))

    def response(self, law=None, drift_rate: float = 0.0, heating: bool = True) -> PlateResponse:
        """The single-mode response at the centre (default law: :func:`.physics.default_law` of the nominal plate;
        with ``heating``, the thermal model of the nominal plate)."""
        nominal = self.nominal.plate()
        law = default_law(nominal) if law is None else law
        return PlateResponse(self.resonance_frequency, self.deflection_per_volt, law, drift_rate,
                             thermal=thermal_model(nominal) if heating else None)

    def spatial_factor(self, x: float, y: float, frequency: float, q: float) -> complex:
        """w(x, y) / w_working(0, 0) at ``frequency`` [Hz] with quality factor ``q`` [-]; (x, y) from the centre [m]."""
        full = self.surface.deflection(x, y, frequency, q)[0]
        working = self.surface.working_deflection(0.0, 0.0, frequency, q)[0]
        return complex(full / working)

    def metadata(self) -> dict:
        """The hidden deviations and the FEM's f_r, for a simulated log's ``simulator_*`` keys."""
        return {**self.deviations.metadata(), "built_resonance_frequency_hz": self.resonance_frequency}


def built_plate_model(nominal: Plate, deviations: PlateDeviations = PlateDeviations(),
                      settings: FemAccuracy | FemSettings = SIMULATION_ACCURACY) -> BuiltPlateModel:
    """Solve the FEM of ``nominal`` built with ``deviations`` (seconds: cache it, see ``workflow.pipeline.builtplate``).

    Parameters
    ----------
    nominal : Plate
        The design [m].
    deviations : PlateDeviations
    settings : FemAccuracy or FemSettings
        FEM accuracy or mesh.
    """
    result, surface = evaluate_surface(deviated_plate(nominal, deviations), PLATE_Q, DESIGN_VOLTAGE, settings)
    return BuiltPlateModel(BuiltPlate.from_plate(nominal), deviations, result, surface)
