"""Everything kincal writes: corrected URDF, frames, reports, plots, all atomically."""

from kincal.lazy import lazy_names

__all__ = ["Outputs", "Written", "write_calibration", "corrected_urdf", "corrected_urdf_text",
           "gate", "result_dict", "html_report", "kinematics_yaml", "mdh_table_csv",
           "write_all"]
__getattr__, __dir__ = lazy_names(__name__, {
    "Outputs": "outputs", "Written": "outputs", "write_calibration": "outputs",
    "corrected_urdf": "outputs", "corrected_urdf_text": "outputs", "gate": "outputs",
    "result_dict": "report", "html_report": "html_report", "kinematics_yaml": "cell_exports",
    "mdh_table_csv": "cell_exports", "write_all": "safe_write"})
