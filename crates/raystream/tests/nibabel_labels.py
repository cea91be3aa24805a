"""nibabel, the NIfTI library TotalSegmentator saves with, as the writer of a multi-label
NIfTI whose header extension holds its label table (Connectome Workbench's XML LabelTable, as
TotalSegmentator's --ml files carry), for tests/volume.rs.
Usage: python nibabel_labels.py IN.nii OUT.nii.gz
Reads the label map IN, adds the extension (ecode 0) naming labels 2, 5 and 7, and saves OUT
(gzip) with nibabel."""
import sys

import nibabel as nib

img = nib.load(sys.argv[1])
labels = [(2, "vertebrae_L1", (0.0, 1.0, 0.0)), (5, "colon", (0.0, 1.0, 1.0)),
          (7, "liver", (1.0, 128 / 255, 0.0))]
rows = "".join(
    f'<Label Key="{k}" Red="{r}" Green="{g}" Blue="{b}" Alpha="1"><![CDATA[{name}]]></Label>\n'
    for k, name, (r, g, b) in labels)
xml = ('<?xml version="1.0" encoding="UTF-8"?>\n<CaretExtension><VolumeInformation Index="0">'
       f"<LabelTable>\n{rows}</LabelTable><VolumeType><![CDATA[Label]]></VolumeType>"
       "</VolumeInformation></CaretExtension>\n")
out = nib.Nifti1Image(img.dataobj, img.affine, img.header)
out.header.extensions.append(nib.nifti1.Nifti1Extension(0, xml.encode("utf-8")))
nib.save(out, sys.argv[2])
