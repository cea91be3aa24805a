"""Writes a DICOM Segmentation of a CT series with highdicom (an independent writer), from a
label map on the series' grid: `highdicom_seg.py SERIES_DIR LABELS.nii.gz OUT.dcm [TYPE]`,
segment n the voxels labelled n (1 and 2); TYPE BINARY (the default) or LABELMAP (DICOM
2024's Label Map Segmentation, a frame a slice)."""
import glob, sys

import highdicom as hd
import numpy as np
import pydicom
import SimpleITK as sitk

series, labels_path, out = sys.argv[1:4]
kind = sys.argv[4] if len(sys.argv) > 4 else "BINARY"
src = sorted((pydicom.dcmread(f) for f in glob.glob(series + "/*.dcm")),
             key=lambda d: float(d.ImagePositionPatient[2]))
labels = sitk.GetArrayFromImage(sitk.ReadImage(labels_path)).astype(np.uint8)  # [k][j][i]
assert labels.shape[0] == len(src)


def segment(n, label, code, meaning):
    return hd.seg.SegmentDescription(
        segment_number=n, segment_label=label,
        segmented_property_category=hd.sr.CodedConcept("123037004", "SCT", "Anatomical Structure"),
        segmented_property_type=hd.sr.CodedConcept(code, "SCT", meaning),
        algorithm_type=hd.seg.SegmentAlgorithmTypeValues.MANUAL)


seg = hd.seg.Segmentation(
    source_images=src, pixel_array=labels,
    segmentation_type=hd.seg.SegmentationTypeValues[kind],
    segment_descriptions=[segment(1, "lumen", "91747007", "Lumen"),
                          segment(2, "wall", "59820001", "Blood vessel")],
    series_instance_uid=hd.UID(), series_number=7, sop_instance_uid=hd.UID(), instance_number=1,
    manufacturer="test", manufacturer_model_name="test", software_versions="0",
    device_serial_number="0")
seg.save_as(out)
