"""Import measured data from lab files (CSV/TSV in any dialect, LabVIEW LVM, TDMS, MATLAB .mat)
into the ``mpc-actuator-data/1`` format.

Entry point :func:`import_lab_files` (mapping file schema in :mod:`.mapping`); readers
:func:`read_lab_file`, :func:`read_text_table`, :func:`read_lvm`, :func:`read_tdms`,
:func:`read_mat`; the CLI (``mpc-actuator import``, harness/cli.py) calls :func:`import_lab_files`; every problem is a
:class:`LabImportError` (a ValueError) naming file, line, column or mapping key.
"""
from harness.data.labimport.csvdialect import TextOptions, read_text_table
from harness.data.labimport.errors import LabImportError
from harness.data.labimport.importer import import_lab_files, read_lab_file
from harness.data.labimport.lvm import read_lvm
from harness.data.labimport.mapping import MAPPING_FORMAT
from harness.data.labimport.matfile import read_mat
from harness.data.labimport.table import Channel, Table
from harness.data.labimport.tdms import read_tdms
from harness.data.labimport.units import split_unit, unit_factor

__all__ = ["import_lab_files", "read_lab_file", "read_text_table", "read_lvm", "read_tdms", "read_mat",
           "TextOptions", "LabImportError", "Channel", "Table", "MAPPING_FORMAT", "split_unit", "unit_factor"]
