// igtl_send_image - a small OpenIGTLink client built on the library's igtl::ImageMessage (the
// way Slicer sends a volume): sends a file's volume as a 3-D IMAGE, or a single slice like
// the Imager examples, then prints the STATUS the server answers with.
// Usage: igtl_send_image HOST PORT FILE|slice
// Exit 0 when a STATUS came back (printed "STATUS code C: TEXT"), 1 otherwise.
#include <cstring>
#include <iostream>

#include <igtlClientSocket.h>
#include <igtlMessageHeader.h>
#include <igtlStatusMessage.h>

#include "isotouch/tests/igtl_test_sender.h"
#include "isotouch/io/volume_io.h"

int main(int argc, char** argv) {
  if (argc != 4) {
    std::cerr << "usage: igtl_send_image HOST PORT FILE|slice\n";
    return 2;
  }
  const std::vector<std::uint8_t> msg =
      std::strcmp(argv[3], "slice") == 0
          ? isotouch::test::single_slice()
          : isotouch::test::image_of(isotouch::io::load_volume(argv[3]), igtl::ImageMessage::ENDIAN_LITTLE);
  igtl::ClientSocket::Pointer s = igtl::ClientSocket::New();
  if (s->ConnectToServer(argv[1], std::atoi(argv[2])) != 0) {
    std::cerr << "igtl_send_image: cannot connect to " << argv[1] << ":" << argv[2] << "\n";
    return 1;
  }
  s->SetReceiveTimeout(10000);  // the server answers within this, or the test fails
  s->Send(msg.data(), int(msg.size()));
  for (int i = 0; i < 1000; ++i) {  // skip the display TRANSFORMs until the STATUS
    igtl::MessageHeader::Pointer h = igtl::MessageHeader::New();
    h->InitPack();
    if (s->Receive(h->GetPackPointer(), h->GetPackSize()) != h->GetPackSize()) break;
    h->Unpack();
    if (std::strcmp(h->GetDeviceType(), "STATUS") != 0) {
      s->Skip(h->GetBodySizeToRead(), 0);
      continue;
    }
    igtl::StatusMessage::Pointer st = igtl::StatusMessage::New();
    st->SetMessageHeader(h);
    st->AllocatePack();
    s->Receive(st->GetPackBodyPointer(), st->GetPackBodySize());
    if (!(st->Unpack(1) & igtl::MessageHeader::UNPACK_BODY)) break;
    std::cout << "STATUS code " << st->GetCode() << ": " << st->GetStatusString() << "\n";
    s->CloseSocket();
    return 0;
  }
  std::cerr << "igtl_send_image: no STATUS came back\n";
  return 1;
}
