"""Every model's report page, by the fit's class: :func:`write_model_page`.

The surface and the thermodynamic model have pages of their own (``surface.html``,
``thermodynamic.html``); any other fitted model gets the generic page of
:mod:`uq._report.model_page` (``<name>.html``). A model plugged in from outside adds its own with
``write_model_page.register(ItsFitClass, its_page_function)``, the function taking
``(fit, result, out_dir, *, figure_format)`` and returning the page's path.
"""

from __future__ import annotations

from uq._models.surface import SurfaceFit
from uq._models.thermo import ThermoFit
from uq._report.model_page import write_model_page
from uq._report.surface import write_surface_report
from uq._report.thermo import write_thermo_report

write_model_page.register(SurfaceFit, write_surface_report)
write_model_page.register(ThermoFit, write_thermo_report)

__all__ = ["write_model_page"]
