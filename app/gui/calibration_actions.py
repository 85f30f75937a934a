"""The Calibration menu's work: the wizard, the Allan variance page, and profiles to and
from files."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from app.core.calibration_procedures import ProfileError
from app.core.calibration_procedures.profiles import read_profile_file
from app.gui import file_dialogs
from app.gui.calibration_wizard import CalibrationWizard

if TYPE_CHECKING:
    from app.gui.allan_page import AllanPage

MainWindow = Any
"""The window this part works for (not imported: the parts sit below
:mod:`app.gui.main_window`, which assembles them)."""


class CalibrationActions:
    """Calibration for ``window``'s device."""

    def __init__(self, window: MainWindow) -> None:
        self.window = window
        self.wizard: CalibrationWizard | None = None
        self.allan_page: AllanPage | None = None

    def open_wizard(self) -> CalibrationWizard | None:
        """Open the (non-modal) wizard for the connected device."""
        window = self.window
        if window.session.device_info is None:
            window.show_error("Connect a device before calibrating it.")
            return None
        if self.wizard is not None and self.wizard.isVisible():
            self.wizard.raise_()
            return self.wizard
        wizard = CalibrationWizard(window.session, window)
        wizard.profileAccepted.connect(window.session.requestProfile)
        self.wizard = wizard
        wizard.show()
        return wizard

    def open_allan_page(self) -> AllanPage:
        """The Allan variance page (a window); its button tunes the filters' noise figures."""
        from app.gui.allan_page import AllanPage

        page = self.allan_page
        if page is None:
            session = self.window.session

            def current(name: str, keys: list[str]) -> dict[str, float] | None:
                running = session.pipeline.filter
                if running.name != name:
                    return None
                return {key: float(running.get_parameter(key)) for key in keys}

            page = AllanPage(settings=self.window.sections.settings,
                             current_parameters=current)
            page.parametersApplied.connect(self.apply_noise_parameters)
            self.allan_page = page
        page.show()
        page.raise_()
        return page

    def apply_noise_parameters(self, name: str, values: dict, source: str) -> None:
        """Set a filter's noise parameters (the running one live) and log where they came from."""
        window = self.window
        listed = ", ".join(f"{key} = {value:.4g}" for key, value in values.items())
        if name == window.filter_panel.current_filter:
            for key, value in values.items():
                window.session.requestFilterParameter.emit(key, value)
            window.log(f"{name}: {listed} set from {source}")
        else:
            window.log(f"{name} (not running): {listed} from {source}; choose {name} and set "
                       "them again to use them")

    def import_profile(self, path: str | None = None) -> None:
        window = self.window
        info = window.session.device_info
        if info is None:
            window.show_error("Connect the device the profile belongs to first.")
            return
        if path is None:
            path = file_dialogs.open_file_name(
                window, "Import calibration profile", "Calibration profiles (*.json)")
            if not path:
                return
        try:
            profile = read_profile_file(Path(path), info.unique_id)
        except (ProfileError, OSError) as exc:
            window.show_error(f"Profile not imported: {exc}")
            return
        window.session.requestProfile.emit(profile)
        window.log(f"Imported calibration profile {path}")

    def export_profile(self, path: str | None = None) -> None:
        window = self.window
        info = window.session.device_info
        if info is None:
            window.show_error("Connect a device to export its profile.")
            return
        if path is None:
            path, _ = file_dialogs.save_file_name(
                window, "Export calibration profile", f"{info.unique_id}.json",
                "Calibration profiles (*.json)",
            )
            if not path:
                return
        try:
            window.session.profile_store.export(info.unique_id, path, overwrite=True)
        except (ProfileError, OSError) as exc:
            window.show_error(f"Profile not exported: {exc}")
            return
        window.log(f"Exported the calibration profile to {path}")

    def show_profile(self, profile) -> None:
        """The worker applied a profile (or none): the status bar, and a line in Messages."""
        self.window.status_view.show_calibration(profile)
        if profile is not None:
            self.window.log(
                f"Calibration applied: {profile.calibration.name} ({profile.method})")
