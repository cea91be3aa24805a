"""Writes a DICOM Segmentation of a CT series with highdicom (an independent writer), from a
label map on the series' grid: `highdicom_seg.py SERIES_DIR LABELS.nii.gz OUT.dcm [TYPE [TS]]`,
segment n the voxels labelled n (1 and 2); TYPE BINARY (the default), FRACTIONAL (each
segment's fraction, 0 or the maximum), OVERLAP (BINARY, and a third segment over both) or
LABELMAP (DICOM 2024's Label Map Segmentation, a frame a slice); TS the transfer syntax: native (the default, Explicit VR Little Endian), rle
(RLE Lossless), jpegls (JPEG-LS Lossless), j2k (JPEG 2000 Lossless) or deflated (native, the
data set deflated by pydicom)."""
import glob, sys

import highdicom as hd
import numpy as np
import pydicom
import SimpleITK as sitk

series, labels_path, out = sys.argv[1:4]
kind = sys.argv[4] if len(sys.argv) > 4 else "BINARY"
ts_name = sys.argv[5] if len(sys.argv) > 5 else "native"
ts = {"native": pydicom.uid.ExplicitVRLittleEndian, "deflated": pydicom.uid.ExplicitVRLittleEndian,
      "rle": pydicom.uid.RLELossless, "jpegls": pydicom.uid.JPEGLSLossless,
      "j2k": pydicom.uid.JPEG2000Lossless}[ts_name]
src = sorted((pydicom.dcmread(f) for f in glob.glob(series + "/*.dcm")),
             key=lambda d: float(d.ImagePositionPatient[2]))
labels = sitk.GetArrayFromImage(sitk.ReadImage(labels_path)).astype(np.uint8)  # [k][j][i]
assert labels.shape[0] == len(src)


def segment(n, label, code, meaning, region=None):
    return hd.seg.SegmentDescription(
        segment_number=n, segment_label=label,
        segmented_property_category=hd.sr.CodedConcept("123037004", "SCT", "Anatomical Structure"),
        segmented_property_type=hd.sr.CodedConcept(code, "SCT", meaning),
        algorithm_type=hd.seg.SegmentAlgorithmTypeValues.MANUAL,
        anatomic_regions=[region] if region else None)


# The lumen's segment names the vessel it lies in (its Anatomic Region), and that region's side
# (an Anatomic Region Modifier, set below: highdicom takes no modifier).
segments = [segment(1, "lumen", "91747007", "Lumen",
                    hd.sr.CodedConcept("73634005", "SCT", "Common iliac artery")),
            segment(2, "wall", "59820001", "Blood vessel")]
if kind == "FRACTIONAL":
    # One fraction a segment, along a last axis.
    labels = np.stack([labels == 1, labels == 2], axis=-1).astype(np.float32)
elif kind == "OVERLAP":
    # BINARY, with a third segment over both: the vessel, lumen and wall together.
    kind = "BINARY"
    labels = np.stack([labels == 1, labels == 2, labels > 0], axis=-1).astype(np.uint8)
    segments.append(segment(3, "vessel", "59820001", "Blood vessel"))
seg = hd.seg.Segmentation(
    source_images=src, pixel_array=labels, transfer_syntax_uid=ts,
    segmentation_type=hd.seg.SegmentationTypeValues[kind],
    segment_descriptions=segments,
    series_instance_uid=hd.UID(), series_number=7, sop_instance_uid=hd.UID(), instance_number=1,
    manufacturer="test", manufacturer_model_name="test", software_versions="0",
    device_serial_number="0")
right = pydicom.Dataset()
right.CodeValue, right.CodingSchemeDesignator, right.CodeMeaning = "24028007", "SCT", "Right"
lumen = next(s for s in seg.SegmentSequence if s.SegmentNumber == 1)
lumen.AnatomicRegionSequence[0].AnatomicRegionModifierSequence = [right]
if ts_name == "deflated":
    seg.file_meta.TransferSyntaxUID = pydicom.uid.DeflatedExplicitVRLittleEndian
seg.save_as(out, enforce_file_format=True)
